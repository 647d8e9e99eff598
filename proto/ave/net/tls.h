#pragma once
// Transport security for every AVE channel (issue 8): TLS with a site CA (deploy/make-certs.sh),
// optionally mutual TLS so that sensor nodes prove themselves with a client certificate too.
// An empty CA file on a client, or an empty certificate on the server, means plaintext, which
// only loopback use should choose.
#include <memory>
#include <string>

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
};

struct TlsServerOptions {
  std::string cert_file;       // PEM server certificate chain; empty = plaintext
  std::string key_file;        // PEM private key
  std::string client_ca_file;  // PEM CA for client certificates; empty = no client certificates
  bool require_client_cert = false;  // refuse handshakes without a client certificate signed by client_ca_file
};

// The file's bytes, or NotFound/Unavailable naming the file and what it was for.
absl::StatusOr<std::string> ReadSmallFile(const std::string& path, const std::string& what);

absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> ClientCredentials(const TlsClientOptions& options);
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentials(const TlsServerOptions& options);

// A channel to `target` with the credentials above. `args` may carry further channel arguments.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& target, const TlsClientOptions& options,
                                                           grpc::ChannelArguments args = {});

}  // namespace ave::net
