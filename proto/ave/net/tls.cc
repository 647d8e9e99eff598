#include "ave/net/tls.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <memory>
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

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};

std::unique_ptr<BIO, BioFree> MemoryBio(const std::string& bytes) {
  return std::unique_ptr<BIO, BioFree>(BIO_new_mem_buf(bytes.data(), static_cast<int>(bytes.size())));
}

}  // namespace

absl::Status CheckKeyMatchesCertificate(const std::string& cert_pem, const std::string& cert_label,
                                        const std::string& key_pem, const std::string& key_label) {
  ERR_clear_error();
  std::unique_ptr<X509, X509Free> cert(PEM_read_bio_X509(MemoryBio(cert_pem).get(), nullptr, nullptr, nullptr));
  if (!cert) return absl::InvalidArgumentError(cert_label + ": holds no certificate (first PEM block is not one)");
  // A null password callback with an empty password: an encrypted key fails here, named as such.
  char empty[] = "";
  std::unique_ptr<EVP_PKEY, KeyFree> key(PEM_read_bio_PrivateKey(MemoryBio(key_pem).get(), nullptr, nullptr, empty));
  ERR_clear_error();
  if (!key) {
    return absl::InvalidArgumentError(key_label +
                                      ": holds no readable private key (not a key, or encrypted with a passphrase)");
  }
  if (X509_check_private_key(cert.get(), key.get()) != 1) {
    ERR_clear_error();
    return absl::InvalidArgumentError(key_label + " is not the private key of " + cert_label +
                                      " (the pair does not match: every TLS handshake would fail)");
  }
  return absl::OkStatus();
}

namespace {

struct ListenParts {
  std::string host;  // without brackets; empty = every address
  std::string port;
  long port_number = 0;
};

// host and port of a listen address, or why it has none usable. Unix sockets have neither.
absl::StatusOr<ListenParts> SplitListenAddress(const std::string& address) {
  std::string rest = address;
  for (const char* scheme : {"dns:///", "dns:", "ipv4:", "ipv6:"}) {
    if (StartsWith(rest, scheme)) rest = rest.substr(std::strlen(scheme));
  }
  const size_t colon = rest.rfind(':');
  if (colon == std::string::npos || colon + 1 == rest.size() || rest.back() == ']') {
    return absl::InvalidArgumentError("cannot listen on " + address + ": no port (want host:port)");
  }
  ListenParts parts;
  parts.port = rest.substr(colon + 1);
  parts.host = rest.substr(0, colon);
  if (StartsWith(parts.host, "[") && parts.host.size() >= 2 && parts.host.back() == ']') {
    parts.host = parts.host.substr(1, parts.host.size() - 2);
  }
  char* end = nullptr;
  errno = 0;
  parts.port_number = std::strtol(parts.port.c_str(), &end, 10);
  if (end == parts.port.c_str() || *end != '\0' || errno != 0 || parts.port_number < 0 || parts.port_number > 65535) {
    return absl::InvalidArgumentError("cannot listen on " + address + ": port '" + parts.port +
                                      "' is not in 0..65535");
  }
  return parts;
}

bool IsUnixAddress(std::string_view address) {
  return StartsWith(address, "unix:") || StartsWith(address, "unix-abstract:");
}

}  // namespace

absl::Status CheckListenAddressSyntax(const std::string& address) {
  if (IsUnixAddress(address)) return absl::OkStatus();
  return SplitListenAddress(address).status();
}

absl::Status ExplainUnusableListenAddress(const std::string& address) {
  if (IsUnixAddress(address)) {
    return absl::UnavailableError("cannot listen on " + address + " (unix socket: is the folder writable?)");
  }
  absl::StatusOr<ListenParts> split = SplitListenAddress(address);
  if (!split.ok()) return split.status();
  const std::string& host = split->host;
  const std::string& port = split->port;
  const long port_number = split->port_number;
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  const int gai = getaddrinfo(host.empty() ? nullptr : host.c_str(), port.c_str(), &hints, &found);
  if (gai != 0) {
    return absl::InvalidArgumentError("cannot listen on " + address + ": host '" + host + "' does not resolve (" +
                                      gai_strerror(gai) + ")");
  }
  std::string reason = "no address to bind";
  for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
    const int fd = ::socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) {
      reason = std::strerror(errno);
      continue;
    }
    const int one = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
    const int rc = ::bind(fd, a->ai_addr, a->ai_addrlen);
    const int err = errno;
    ::close(fd);
    if (rc == 0) {
      reason = "";
      break;
    }
    reason = std::strerror(err);
    if (err == EADDRINUSE) reason += ": another program (or another ave-server) holds the port";
    if (err == EACCES && port_number < 1024) reason += ": ports below 1024 need privilege";
    if (err == EADDRNOTAVAIL) reason += ": the address is not one of this host's";
  }
  freeaddrinfo(found);
  if (reason.empty()) {
    // Bindable now: what failed was gRPC's own listener (e.g. a race for the port, or the port is
    // bound with SO_REUSEPORT by another gRPC server that is not accepting).
    return absl::UnavailableError("cannot listen on " + address + " (gRPC refused the address; bindable now, retry)");
  }
  return absl::UnavailableError("cannot listen on " + address + " (" + reason + ")");
}

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
    absl::Status pair = CheckKeyMatchesCertificate(*cert, "TLS client certificate '" + options.cert_file + "'", *key,
                                                   "TLS client key '" + options.key_file + "'");
    if (!pair.ok()) return pair;
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
  absl::Status pair = CheckKeyMatchesCertificate(*cert, "TLS server certificate '" + options.cert_file + "'", *key,
                                                 "TLS server key '" + options.key_file + "'");
  if (!pair.ok()) return pair;
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
