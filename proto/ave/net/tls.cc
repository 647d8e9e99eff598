#include "ave/net/tls.h"

#include <arpa/inet.h>
#include <netinet/in.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>

namespace ave::net {
namespace {

bool StartsWith(std::string_view s, std::string_view prefix) { return s.substr(0, prefix.size()) == prefix; }

// The host of "host:port", "[v6]:port", "host" or a bare IPv6 address (two colons or more).
std::string_view HostOf(std::string_view host_port) {
  if (StartsWith(host_port, "[")) {
    const size_t close = host_port.find(']');
    return close == std::string_view::npos ? std::string_view{} : host_port.substr(1, close - 1);
  }
  if (std::count(host_port.begin(), host_port.end(), ':') > 1) return host_port;
  return host_port.substr(0, host_port.find(':'));
}

bool IsLoopbackHost(std::string_view host) {
  std::string h(host);
  std::transform(h.begin(), h.end(), h.begin(), [](unsigned char c) { return std::tolower(c); });
  if (h == "localhost" || h == "localhost.") return true;
  in_addr v4{};
  if (inet_pton(AF_INET, h.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  if (inet_pton(AF_INET6, h.c_str(), &v6) == 1) {
    if (IN6_IS_ADDR_LOOPBACK(&v6)) return true;
    return IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127;
  }
  return false;  // 0.0.0.0, ::, empty, or a name that could resolve anywhere
}

}  // namespace

bool IsLoopbackAddress(std::string_view address) {
  if (StartsWith(address, "unix:") || StartsWith(address, "unix-abstract:")) return true;
  if (StartsWith(address, "dns:")) {
    address.remove_prefix(4);
    if (StartsWith(address, "//")) {  // dns://[authority]/host:port
      const size_t slash = address.find('/', 2);
      if (slash == std::string_view::npos) return false;
      address.remove_prefix(slash + 1);
    }
    return IsLoopbackHost(HostOf(address));
  }
  if (StartsWith(address, "ipv4:") || StartsWith(address, "ipv6:")) {
    address.remove_prefix(5);
    if (address.empty()) return false;
    while (!address.empty()) {  // a comma-separated list: every address must be loopback
      const size_t comma = address.find(',');
      if (!IsLoopbackHost(HostOf(address.substr(0, comma)))) return false;
      address.remove_prefix(comma == std::string_view::npos ? address.size() : comma + 1);
    }
    return true;
  }
  return IsLoopbackHost(HostOf(address));
}

absl::Status CheckClientTransport(const std::string& target, const TlsClientOptions& options) {
  if (!options.ca_file.empty() || options.insecure_plaintext || IsLoopbackAddress(target)) return absl::OkStatus();
  return absl::FailedPreconditionError(
      "refusing to send a bearer token in plaintext to non-loopback server '" + target +
      "': pass --tls-ca CA.pem (TLS), or --insecure-plaintext to let the token cross the network in clear");
}

absl::Status CheckServerTransport(const std::string& address, const TlsServerOptions& options) {
  if (!options.cert_file.empty() || options.insecure_plaintext || IsLoopbackAddress(address)) return absl::OkStatus();
  return absl::FailedPreconditionError(
      "refusing to listen on non-loopback address '" + address +
      "' in plaintext (bearer tokens would cross the network in clear): pass --tls-cert/--tls-key to serve TLS, "
      "or --insecure-plaintext to accept that");
}

absl::StatusOr<std::string> ReadSmallFile(const std::string& path, const std::string& what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(what + " '" + path + "': cannot open");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!in.good() && !in.eof()) return absl::UnavailableError(what + " '" + path + "': read failed");
  std::string s = bytes.str();
  if (s.size() > (1 << 20)) return absl::InvalidArgumentError(what + " '" + path + "': larger than 1 MiB");
  if (s.find("-----BEGIN") == std::string::npos) {
    return absl::InvalidArgumentError(what + " '" + path + "': not a PEM file");
  }
  return s;
}

absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ClientCredentials(const TlsClientOptions& options) {
  if (options.ca_file.empty()) {
    if (!options.cert_file.empty()) return absl::InvalidArgumentError("a client certificate needs --tls-ca too");
    return grpc::InsecureChannelCredentials();
  }
  if (options.cert_file.empty() != options.key_file.empty()) {
    return absl::InvalidArgumentError("client certificate and key go together (--tls-cert with --tls-key)");
  }
  grpc::SslCredentialsOptions ssl;
  absl::StatusOr<std::string> ca = ReadSmallFile(options.ca_file, "TLS CA");
  if (!ca.ok()) return ca.status();
  ssl.pem_root_certs = *ca;
  if (!options.cert_file.empty()) {
    absl::StatusOr<std::string> cert = ReadSmallFile(options.cert_file, "TLS client certificate");
    if (!cert.ok()) return cert.status();
    absl::StatusOr<std::string> key = ReadSmallFile(options.key_file, "TLS client key");
    if (!key.ok()) return key.status();
    ssl.pem_cert_chain = *cert;
    ssl.pem_private_key = *key;
  }
  return grpc::SslCredentials(ssl);
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentials(const TlsServerOptions& options) {
  if (options.cert_file.empty()) {
    if (!options.key_file.empty() || !options.client_ca_file.empty()) {
      return absl::InvalidArgumentError("--tls-key and --tls-client-ca need --tls-cert");
    }
    return grpc::InsecureServerCredentials();
  }
  if (options.key_file.empty()) return absl::InvalidArgumentError("--tls-cert needs --tls-key");
  if (options.require_client_cert && options.client_ca_file.empty()) {
    return absl::InvalidArgumentError("requiring client certificates needs --tls-client-ca");
  }
  absl::StatusOr<std::string> cert = ReadSmallFile(options.cert_file, "TLS server certificate");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = ReadSmallFile(options.key_file, "TLS server key");
  if (!key.ok()) return key.status();
  grpc::SslServerCredentialsOptions ssl(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  ssl.pem_key_cert_pairs.push_back({*key, *cert});
  if (!options.client_ca_file.empty()) {
    absl::StatusOr<std::string> ca = ReadSmallFile(options.client_ca_file, "TLS client CA");
    if (!ca.ok()) return ca.status();
    ssl.pem_root_certs = *ca;
    // Without require_client_cert, viewers and administrators may connect without a certificate;
    // a certificate that is presented must verify. The sensor role then checks that one was.
    ssl.client_certificate_request = options.require_client_cert
                                         ? GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY
                                         : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(ssl);
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& target, const TlsClientOptions& options,
                                                           grpc::ChannelArguments args) {
  if (absl::Status s = CheckClientTransport(target, options); !s.ok()) return s;
  absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials = ClientCredentials(options);
  if (!credentials.ok()) return credentials.status();
  if (!options.server_name.empty()) args.SetSslTargetNameOverride(options.server_name);
  return grpc::CreateCustomChannel(target, *credentials, args);
}

}  // namespace ave::net
