// Issue 8: roles and tokens checked on every call, TLS and mutual TLS for sensors on loopback,
// the gRPC health service and the Prometheus metrics endpoint.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "ave/net/tls.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/auth.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "model_store/common/log.h"
#include "model_store/db/store.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
using fixtures::CameraRecord;
using fixtures::Jpeg;
using ::testing::Not;

constexpr char kAdmin[] = "bootstrap-admin";
constexpr char kViewer[] = "bootstrap-viewer";

// A fresh CA and certificates from deploy/make-certs.sh, once per test binary.
const std::filesystem::path& Certs() {
  static const std::filesystem::path dir = [] {
    const auto d = std::filesystem::temp_directory_path() / ("ave_certs_" + std::to_string(::getpid()));
    const std::string cmd = std::string("bash ") + AVE_SOURCE_DIR + "/deploy/make-certs.sh " + d.string() +
                            " cam-a >/dev/null 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    // A second, unrelated CA to show that a client trusting the wrong CA is refused.
    const std::string other = std::string("bash ") + AVE_SOURCE_DIR + "/deploy/make-certs.sh " + (d / "other").string() +
                              " x >/dev/null 2>&1";
    EXPECT_EQ(std::system(other.c_str()), 0) << other;
    return d;
  }();
  return dir;
}

class Fixture : public ::testing::Test {
 protected:
  void StartServer(const net::TlsServerOptions& tls = {}, bool sensor_cert = false) {
    // No bootstrap sensor token: sensors use issued, per-camera tokens.
    ServerOptions options = server_.Options("", kViewer, kAdmin);
    options.tls = tls;
    options.sensor_requires_client_cert = sensor_cert;
    options.metrics_listen = "127.0.0.1:0";
    options.campus_grid_m = 8;
    const absl::Status started = server_.Start(options);
    ASSERT_TRUE(started.ok()) << started;
    address_ = server_.address();
  }

  std::shared_ptr<grpc::Channel> Channel(const net::TlsClientOptions& tls = {}) {
    auto channel = net::MakeChannel(address_, tls);
    EXPECT_TRUE(channel.ok()) << channel.status();
    return *channel;
  }

  static grpc::Status AdminCall(grpc::Channel* channel, const std::string& token,
                                const std::function<grpc::Status(v1::AdminService::Stub&, grpc::ClientContext&)>& call) {
    auto stub = v1::AdminService::NewStub(std::shared_ptr<grpc::Channel>(channel, [](grpc::Channel*) {}));
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    return call(*stub, context);
  }

  static grpc::Status AddCamera(grpc::Channel* channel, const std::string& token, const std::string& id) {
    return AdminCall(channel, token, [&](v1::AdminService::Stub& stub, grpc::ClientContext& context) {
      v1::AddCameraRequest request;
      *request.mutable_camera() = CameraRecord(id);
      v1::Camera response;
      return stub.AddCamera(&context, request, &response);
    });
  }

  static std::string IssueToken(grpc::Channel* channel, const std::string& role, const std::string& camera,
                                grpc::Status* status = nullptr, const std::string& token = kAdmin) {
    v1::IssueTokenResponse response;
    const grpc::Status s = AdminCall(channel, token, [&](v1::AdminService::Stub& stub, grpc::ClientContext& context) {
      v1::IssueTokenRequest request;
      request.set_role(role);
      request.set_camera_id(camera);
      request.set_label("test " + role);
      return stub.IssueToken(&context, request, &response);
    });
    if (status) *status = s;
    return response.token();
  }

  // Hello + two frames as `camera` with `token`; the final status.
  static grpc::Status Stream(grpc::Channel* channel, const std::string& camera, const std::string& token,
                             int* acks = nullptr) {
    auto stub = v1::SensorService::NewStub(std::shared_ptr<grpc::Channel>(channel, [](grpc::Channel*) {}));
    v1::SensorHello hello;
    hello.set_camera_id(camera);
    hello.set_token(token);
    *hello.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
    std::vector<v1::SensorFrame> frames(2);
    for (uint64_t seq = 1; seq <= 2; ++seq) {
      frames[seq - 1].set_sequence(seq);
      frames[seq - 1].set_capture_time_ns(NowNs());
      frames[seq - 1].set_jpeg(Jpeg(64, 48));
    }
    return fixtures::StreamFrames(*stub, hello, frames, acks);
  }

  // Subscribe and read one update; the final status (OK when an update arrived and we cancelled).
  static grpc::Status Subscribe(grpc::Channel* channel, const std::string& token, v1::SceneUpdate* update = nullptr) {
    auto stub = v1::SceneService::NewStub(std::shared_ptr<grpc::Channel>(channel, [](grpc::Channel*) {}));
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    v1::SubscribeRequest request;
    request.set_include_jpeg(true);
    auto reader = stub->Subscribe(&context, request);
    v1::SceneUpdate local;
    if (reader->Read(update ? update : &local)) {
      context.TryCancel();
      reader->Finish();
      return grpc::Status::OK;
    }
    return reader->Finish();
  }

  fixtures::LocalServer server_{"ave_roles_test"};
  std::string address_;
};

using Roles = Fixture;

TEST_F(Roles, EachRoleIsRefusedOutsideItsRights) {
  StartServer();
  auto channel = Channel();
  ASSERT_TRUE(AddCamera(channel.get(), kAdmin, "cam-a").ok());
  ASSERT_TRUE(AddCamera(channel.get(), kAdmin, "cam-b").ok());
  grpc::Status s;
  const std::string sensor_a = IssueToken(channel.get(), "sensor", "cam-a", &s);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const std::string viewer = IssueToken(channel.get(), "viewer", "", &s);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const std::string admin2 = IssueToken(channel.get(), "admin", "", &s);
  ASSERT_TRUE(s.ok()) << s.error_message();

  // sensor: streams as its own camera only; nothing else.
  int acks = 0;
  s = Stream(channel.get(), "cam-a", sensor_a, &acks);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(acks, 2);
  s = Stream(channel.get(), "cam-b", sensor_a);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(s.error_message(), HasSubstr("bound to camera 'cam-a'"));
  EXPECT_EQ(server_->state().AcceptedCount("cam-b"), 0u);
  s = Subscribe(channel.get(), sensor_a);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(s.error_message(), HasSubstr("role sensor"));
  EXPECT_EQ(AddCamera(channel.get(), sensor_a, "cam-x").error_code(), grpc::StatusCode::PERMISSION_DENIED);

  // viewer: subscribes only.
  v1::SceneUpdate update;
  EXPECT_TRUE(Subscribe(channel.get(), viewer, &update).ok());
  EXPECT_EQ(update.cameras_size(), 2);
  s = Stream(channel.get(), "cam-a", viewer);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(s.error_message(), HasSubstr("only sensor tokens stream"));
  s = AddCamera(channel.get(), viewer, "cam-x");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_THAT(s.error_message(), HasSubstr("manage cameras"));
  IssueToken(channel.get(), "admin", "", &s, viewer);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);

  // admin (issued): manages cameras, may not stream.
  EXPECT_TRUE(AddCamera(channel.get(), admin2, "cam-c").ok());
  EXPECT_EQ(Stream(channel.get(), "cam-c", admin2).error_code(), grpc::StatusCode::PERMISSION_DENIED);

  // Unknown tokens are unauthenticated, on every service.
  EXPECT_EQ(Stream(channel.get(), "cam-a", "guess").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(Subscribe(channel.get(), "guess").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(AddCamera(channel.get(), "guess", "cam-y").error_code(), grpc::StatusCode::UNAUTHENTICATED);

  // A sensor token must name a registered camera.
  IssueToken(channel.get(), "sensor", "", &s);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  IssueToken(channel.get(), "sensor", "nope", &s);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(Roles, TokensAreStoredHashedSurviveRestartAndRevocationBites) {
  StartServer();
  auto channel = Channel();
  ASSERT_TRUE(AddCamera(channel.get(), kAdmin, "cam-a").ok());
  grpc::Status s;
  const std::string sensor = IssueToken(channel.get(), "sensor", "cam-a", &s);
  ASSERT_TRUE(s.ok());
  const std::string store_path = server_.store_path();
  server_.Stop();
  {
    auto store = store::Store::Open(store_path);
    ASSERT_TRUE(store.ok());
    auto tokens = (*store)->ListTokens();
    ASSERT_TRUE(tokens.ok());
    ASSERT_EQ(tokens->size(), 1u);
    EXPECT_EQ((*tokens)[0].hash, HashToken(sensor));
    auto audit = (*store)->ListAudit();
    ASSERT_TRUE(audit.ok());
    bool issued = false;
    for (const auto& a : *audit) {
      issued |= a.action == "IssueToken";
      EXPECT_THAT(a.after_json + a.actor, Not(HasSubstr(sensor)));  // the token never reaches the audit
      EXPECT_THAT(a.actor, HasSubstr("admin:"));
    }
    EXPECT_TRUE(issued);
  }
  // Nothing in the database file (or its WAL) holds the token itself.
  for (const char* suffix : {"", "-wal"}) {
    std::ifstream in(store_path + suffix, std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    EXPECT_EQ(bytes.str().find(sensor), std::string::npos) << suffix;
  }
  // After a restart the issued token still works (loaded from the store), until revoked.
  ServerOptions options = server_.Options("", "", kAdmin);
  options.campus_grid_m = 8;
  const absl::Status restarted = server_.Start(options);
  ASSERT_TRUE(restarted.ok()) << restarted;
  address_ = server_.address();
  channel = Channel();
  EXPECT_TRUE(Stream(channel.get(), "cam-a", sensor).ok());
  s = AdminCall(channel.get(), kAdmin, [&](v1::AdminService::Stub& stub, grpc::ClientContext& context) {
    v1::RevokeTokenRequest request;
    request.set_token_id(HashToken(sensor).substr(0, 12));
    v1::RevokeTokenResponse response;
    return stub.RevokeToken(&context, request, &response);
  });
  ASSERT_TRUE(s.ok()) << s.error_message();
  s = Stream(channel.get(), "cam-a", sensor);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_THAT(s.error_message(), HasSubstr("camera 'cam-a'"));
}

TEST_F(Roles, AStoredTokenWithAnUnknownRoleIsRefusedAndNamedInTheLog) {
  StartServer();
  auto channel = Channel();
  ASSERT_TRUE(AddCamera(channel.get(), kAdmin, "cam-a").ok());
  grpc::Status s;
  const std::string sensor = IssueToken(channel.get(), "sensor", "cam-a", &s);
  ASSERT_TRUE(s.ok());
  const std::string viewer = IssueToken(channel.get(), "viewer", "", &s);
  ASSERT_TRUE(s.ok());
  const std::string store_path = server_.store_path();
  server_.Stop();
  // A row a newer release (or a hand edit) wrote with a role this server does not know.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(store_path.c_str(), &db), SQLITE_OK);
  const std::string edit = "UPDATE tokens SET role = 'operator' WHERE hash = '" + HashToken(sensor) + "'";
  EXPECT_EQ(sqlite3_exec(db, edit.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
  EXPECT_EQ(sqlite3_changes(db), 1);
  sqlite3_close(db);

  ServerOptions options = server_.Options("", "", kAdmin);
  options.campus_grid_m = 8;
  testing::internal::CaptureStderr();
  const absl::Status restarted = server_.Start(options);
  const std::string log = testing::internal::GetCapturedStderr();
  ASSERT_TRUE(restarted.ok()) << restarted;
  EXPECT_THAT(log, HasSubstr("token " + HashToken(sensor).substr(0, 12)));
  EXPECT_THAT(log, HasSubstr("role 'operator'"));
  address_ = server_.address();
  channel = Channel();
  s = Stream(channel.get(), "cam-a", sensor);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << s.error_message();
  EXPECT_TRUE(Subscribe(channel.get(), viewer).ok());  // the other rows still load
}

using Tls = Fixture;

net::TlsServerOptions ServerTls(bool mutual) {
  net::TlsServerOptions tls;
  tls.cert_file = (Certs() / "server.pem").string();
  tls.key_file = (Certs() / "server.key").string();
  if (mutual) tls.client_ca_file = (Certs() / "ca.pem").string();
  return tls;
}

TEST_F(Tls, ClientsTrustingTheSiteCaConnectOthersDoNot) {
  StartServer(ServerTls(false));
  auto good = Channel({.ca_file = (Certs() / "ca.pem").string()});
  EXPECT_TRUE(AddCamera(good.get(), kAdmin, "cam-a").ok());
  EXPECT_TRUE(Subscribe(good.get(), kViewer).ok());
  // Plaintext against a TLS port, and TLS trusting another CA, both fail at the transport.
  grpc::Status s = AddCamera(Channel().get(), kAdmin, "cam-b");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << s.error_message();
  auto wrong = Channel({.ca_file = (Certs() / "other" / "ca.pem").string()});
  s = AddCamera(wrong.get(), kAdmin, "cam-b");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE) << s.error_message();
  // Misconfiguration names the file.
  auto missing = net::MakeChannel(address_, {.ca_file = "/no/such/ca.pem"});
  EXPECT_THAT(std::string(missing.status().message()), HasSubstr("/no/such/ca.pem"));
}

TEST_F(Tls, ACertificateAndAKeyThatDoNotMatchAreRefusedNamingBoth) {
  net::TlsServerOptions tls = ServerTls(false);
  tls.key_file = (Certs() / "other" / "server.key").string();
  auto credentials = net::ServerCredentials(tls);
  ASSERT_FALSE(credentials.ok());
  EXPECT_EQ(credentials.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(credentials.status().message(), HasSubstr("other/server.key"));
  EXPECT_THAT(credentials.status().message(), HasSubstr("server.pem"));
  EXPECT_THAT(credentials.status().message(), HasSubstr("does not match"));
  // The server does not start on it (it would listen and fail every handshake).
  ServerOptions options = server_.Options("bootstrap-sensor", kViewer, kAdmin);
  options.tls = tls;
  EXPECT_FALSE(server_.Start(options).ok());

  // A client certificate with another sensor's key, and a "key" that is a certificate.
  net::TlsClientOptions client{.ca_file = (Certs() / "ca.pem").string(),
                               .cert_file = (Certs() / "sensor-cam-a.pem").string(),
                               .key_file = (Certs() / "other" / "sensor-x.key").string()};
  auto channel_credentials = net::ClientCredentials(client);
  ASSERT_FALSE(channel_credentials.ok());
  EXPECT_THAT(channel_credentials.status().message(), HasSubstr("TLS client key"));
  EXPECT_THAT(channel_credentials.status().message(), HasSubstr("sensor-x.key"));
  client.key_file = (Certs() / "ca.pem").string();
  channel_credentials = net::ClientCredentials(client);
  ASSERT_FALSE(channel_credentials.ok());
  EXPECT_THAT(channel_credentials.status().message(), HasSubstr("holds no readable private key"));
  // The matching pair is accepted.
  client.key_file = (Certs() / "sensor-cam-a.key").string();
  EXPECT_TRUE(net::ClientCredentials(client).ok());
}

TEST_F(Tls, SensorsMustPresentAClientCertificateWhenMutualTlsIsOn) {
  StartServer(ServerTls(true), /*sensor_cert=*/true);
  const std::string ca = (Certs() / "ca.pem").string();
  auto plain_tls = Channel({.ca_file = ca});  // viewers and admins need no certificate
  ASSERT_TRUE(AddCamera(plain_tls.get(), kAdmin, "cam-a").ok());
  grpc::Status s;
  const std::string sensor = IssueToken(plain_tls.get(), "sensor", "cam-a", &s);
  ASSERT_TRUE(s.ok());
  s = Stream(plain_tls.get(), "cam-a", sensor);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_THAT(s.error_message(), HasSubstr("client certificate"));
  auto mutual = Channel({.ca_file = ca,
                         .cert_file = (Certs() / "sensor-cam-a.pem").string(),
                         .key_file = (Certs() / "sensor-cam-a.key").string()});
  int acks = 0;
  s = Stream(mutual.get(), "cam-a", sensor, &acks);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(acks, 2);
  // A client certificate from another CA fails the handshake.
  auto foreign = Channel({.ca_file = ca,
                          .cert_file = (Certs() / "other" / "sensor-x.pem").string(),
                          .key_file = (Certs() / "other" / "sensor-x.key").string()});
  EXPECT_EQ(Stream(foreign.get(), "cam-a", sensor).error_code(), grpc::StatusCode::UNAVAILABLE);
}

using Operations = Fixture;

std::string HttpGet(int port, const std::string& path) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return "";
  }
  const std::string request = "GET " + path + " HTTP/1.0\r\n\r\n";
  (void)!::send(fd, request.data(), request.size(), 0);
  std::string response;
  char buffer[4096];
  ssize_t n;
  while ((n = ::recv(fd, buffer, sizeof buffer, 0)) > 0) response.append(buffer, static_cast<size_t>(n));
  ::close(fd);
  return response;
}

TEST_F(Operations, HealthServiceServesUntilShutdown) {
  StartServer();
  auto channel = Channel();
  auto health = grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext context;
  grpc::health::v1::HealthCheckRequest request;
  grpc::health::v1::HealthCheckResponse response;
  ASSERT_TRUE(health->Check(&context, request, &response).ok());
  EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING);
}

// Sends `bytes` (nothing if empty) on a fresh connection to the metrics port and returns the reply.
std::string HttpRaw(int port, const std::string& bytes) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return "";
  }
  if (!bytes.empty()) (void)!::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  std::string response;
  char buffer[4096];
  ssize_t n;
  while ((n = ::recv(fd, buffer, sizeof buffer, 0)) > 0) response.append(buffer, static_cast<size_t>(n));
  ::close(fd);
  return response;
}

// Issue 14: the two side doors. An unknown health-service name is NOT_FOUND; an oversized,
// garbage or silent request to the metrics port gets a 404 (or is closed) and the port keeps
// serving.
TEST_F(Operations, UnknownHealthNamesAndBadMetricsRequestsAreRefusedAndServingGoesOn) {
  StartServer();
  auto health = grpc::health::v1::Health::NewStub(Channel());
  grpc::ClientContext context;
  grpc::health::v1::HealthCheckRequest request;
  request.set_service("no.such.Service");
  grpc::health::v1::HealthCheckResponse response;
  EXPECT_EQ(health->Check(&context, request, &response).error_code(), grpc::StatusCode::NOT_FOUND);

  const int port = server_->metrics_port();
  ASSERT_GT(port, 0);
  EXPECT_THAT(HttpRaw(port, std::string(5000, 'A')), HasSubstr("HTTP/1.0 404"));
  EXPECT_THAT(HttpRaw(port, std::string("\x00\xff\r\n\r\n", 6)), HasSubstr("HTTP/1.0 404"));
  EXPECT_THAT(HttpRaw(port, "POST /metrics HTTP/1.0\r\n\r\n"), HasSubstr("HTTP/1.0 404"));
  EXPECT_THAT(HttpRaw(port, ""), HasSubstr("HTTP/1.0 404"));  // silent: answered after the 1 s bound
  EXPECT_THAT(HttpGet(port, "/metrics"), HasSubstr("HTTP/1.0 200 OK"));
}

TEST_F(Operations, MetricsCountFramesInAndOutAndRefusals) {
  StartServer();
  ASSERT_GT(server_->metrics_port(), 0);
  auto channel = Channel();
  ASSERT_TRUE(AddCamera(channel.get(), kAdmin, "cam-a").ok());
  grpc::Status s;
  const std::string sensor = IssueToken(channel.get(), "sensor", "cam-a", &s);
  ASSERT_TRUE(Stream(channel.get(), "cam-a", sensor).ok());
  EXPECT_EQ(Stream(channel.get(), "cam-a", "guess").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  v1::SceneUpdate update;
  ASSERT_TRUE(Subscribe(channel.get(), kViewer, &update).ok());
  ASSERT_EQ(update.cameras_size(), 1);
  EXPECT_FALSE(update.cameras(0).jpeg().empty());
  // The server counts a write after it returns, which can be just after the client has read it.
  std::string body;
  for (int i = 0; i < 100; ++i) {
    body = HttpGet(server_->metrics_port(), "/metrics");
    if (body.find("\nave_frames_out_total 1\n") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_THAT(body, HasSubstr("HTTP/1.0 200 OK"));
  EXPECT_THAT(body, HasSubstr("\nave_frames_in_total 2\n"));
  EXPECT_THAT(body, HasSubstr("\nave_frames_out_total 1\n"));
  EXPECT_THAT(body, HasSubstr("\nave_auth_failures_total 1\n"));
  EXPECT_THAT(body, HasSubstr("ave_capture_to_send_seconds_bucket{le=\"+Inf\"} 1\n"));
  EXPECT_THAT(body, HasSubstr("# TYPE ave_viewers_connected gauge"));
  EXPECT_THAT(HttpGet(server_->metrics_port(), "/nope"), HasSubstr("404"));
}

}  // namespace
}  // namespace ave
