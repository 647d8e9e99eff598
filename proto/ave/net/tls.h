#pragma once
// Transport security for every AVE channel (issue 8): TLS with a site CA (deploy/make-certs.sh),
// optionally mutual TLS so that sensor nodes prove themselves with a client certificate too.
// An empty CA file on a client, or an empty certificate on the server, means plaintext: bearer
// tokens would cross the network in clear, so plaintext is refused off loopback unless the operator
// says `insecure_plaintext` (--insecure-plaintext) (issue 14).
#include <memory>
#include <string>
#include <string_view>

#include <grpcpp/grpcpp.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>

#include "absl/status/statusor.h"

namespace ave::net {

struct TlsClientOptions {
  std::string ca_file;    // PEM CA that signed the server certificate; empty = plaintext
  std::string cert_file;  // PEM client certificate (mutual TLS); with key_file
  std::string key_file;
  // Name the server certificate must carry when it differs from the dialled host (e.g. "localhost").
  std::string server_name;
  // Send the bearer token in plaintext to a non-loopback server anyway (--insecure-plaintext).
  bool insecure_plaintext = false;
};

struct TlsServerOptions {
  std::string cert_file;       // PEM server certificate chain; empty = plaintext
  std::string key_file;        // PEM private key
  std::string client_ca_file;  // PEM CA for client certificates; empty = no client certificates
  bool require_client_cert = false;  // refuse handshakes without a client certificate signed by client_ca_file
  // Serve plaintext on a non-loopback address anyway (--insecure-plaintext).
  bool insecure_plaintext = false;
};

// True when every address `address` names is on this host: 127.0.0.0/8, ::1 (also as
// ::ffff:127.x.y.z), "localhost", or a unix socket. Takes listen addresses and gRPC targets alike:
// "host:port", "[v6]:port", "dns:///host:port", "ipv4:a:p,b:p", "ipv6:[a]:p", "unix:path",
// "unix-abstract:name". 0.0.0.0, [::], an empty host, and every other address or host name are not
// loopback (a name could resolve anywhere).
bool IsLoopbackAddress(std::string_view address);

// OK, or FailedPrecondition naming `target`: without TLS the client would send its bearer token in
// plaintext to a server off this host, and options.insecure_plaintext does not allow it.
absl::Status CheckClientTransport(const std::string& target, const TlsClientOptions& options);

// OK, or FailedPrecondition naming `address`: without TLS the server would take bearer tokens in
// plaintext on an address reachable from the network, and options.insecure_plaintext does not allow it.
absl::Status CheckServerTransport(const std::string& address, const TlsServerOptions& options);

// The file's bytes, or NotFound/Unavailable naming the file and what it was for.
absl::StatusOr<std::string> ReadSmallFile(const std::string& path, const std::string& what);

// OK when `key_pem` is the private key of the first certificate in `cert_pem`; else InvalidArgument
// naming both by their labels (e.g. "TLS server key 'k.pem'"): a certificate that holds none, a
// key that cannot be read (or is encrypted), or a pair that does not match, which would otherwise
// only show as every handshake failing.
absl::Status CheckKeyMatchesCertificate(const std::string& cert_pem, const std::string& cert_label,
                                        const std::string& key_pem, const std::string& key_label);

// OK, or InvalidArgument naming the address: "host:port" (or "[v6]:port", "ipv4:"/"dns:" forms)
// without a port, or with one outside 0..65535 (gRPC would wrap 70000 to 4464 and listen there).
// unix: addresses pass.
absl::Status CheckListenAddressSyntax(const std::string& address);

// Why a listen address that gRPC refused cannot be used, for the error message: a missing or
// out-of-range port, a host that does not resolve, or the bind error itself (address in use,
// not this host's address, a privileged port). Never OK: call it after gRPC failed to listen.
absl::Status ExplainUnusableListenAddress(const std::string& address);

absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ClientCredentials(const TlsClientOptions& options);
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentials(const TlsServerOptions& options);

// A channel to `target` with the credentials above, after CheckClientTransport. `args` may carry
// further channel arguments.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& target, const TlsClientOptions& options,
                                                           grpc::ChannelArguments args = {});

}  // namespace ave::net
