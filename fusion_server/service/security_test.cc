// Issue 14: no secret in clear. The server refuses plaintext off loopback unless told, warns while
// told, and shows it in its metrics; failed authentications are limited per peer, counted and
// audited without flooding the audit table.
#include <atomic>
#include <filesystem>
#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "ave/net/tls.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/db/store.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kAdmin[] = "security-admin";
constexpr int64_t kSecondNs = 1'000'000'000;

// A fresh directory per test for the store.
class TempDir {
 public:
  TempDir() : path_(std::filesystem::temp_directory_path() /
                    ("ave_security_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter_++))) {
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string store() const { return (path_ / "ave.db").string(); }

 private:
  static inline int counter_ = 0;
  std::filesystem::path path_;
};

ServerOptions Options(const TempDir& dir) {
  ServerOptions options = fixtures::LoopbackServer(dir.store(), "", "", kAdmin);
  options.campus_grid_m = 8;
  return options;
}

// The value of an unlabelled metric in the Prometheus text, or -1 when absent.
double Metric(const std::string& text, const std::string& name) {
  const size_t at = text.find("\n" + name + " ");
  if (at == std::string::npos) return -1;
  return std::stod(text.substr(at + name.size() + 2));
}

std::shared_ptr<grpc::Channel> Loopback(int port) {
  auto channel = net::MakeChannel("127.0.0.1:" + std::to_string(port), {});
  EXPECT_TRUE(channel.ok()) << channel.status();
  return *channel;
}

grpc::Status AddCamera(grpc::Channel& channel, const std::string& token, const std::string& id) {
  auto stub = v1::AdminService::NewStub(std::shared_ptr<grpc::Channel>(&channel, [](grpc::Channel*) {}));
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  v1::AddCameraRequest request;
  *request.mutable_camera() = fixtures::CameraRecord(id);
  v1::Camera response;
  return stub->AddCamera(&context, request, &response);
}

grpc::Status Subscribe(grpc::Channel& channel, const std::string& token) {
  auto stub = v1::SceneService::NewStub(std::shared_ptr<grpc::Channel>(&channel, [](grpc::Channel*) {}));
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto reader = stub->Subscribe(&context, v1::SubscribeRequest{});
  v1::SceneUpdate update;
  if (reader->Read(&update)) {
    context.TryCancel();
    reader->Finish();
    return grpc::Status::OK;
  }
  return reader->Finish();
}

grpc::Status Stream(grpc::Channel& channel, const std::string& camera, const std::string& token) {
  auto stub = v1::SensorService::NewStub(std::shared_ptr<grpc::Channel>(&channel, [](grpc::Channel*) {}));
  v1::SensorHello hello;
  hello.set_camera_id(camera);
  hello.set_token(token);
  *hello.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
  return fixtures::StreamFrames(*stub, hello, {});
}

TEST(PlaintextRule, ServerOptionsRefuseANonLoopbackAddressWithoutTlsOrTheFlag) {
  ServerOptions options;
  options.admin_token = kAdmin;
  for (const char* address : {"0.0.0.0:50051", "[::]:50051", "10.0.0.5:50051", "ave-server.example:50051", ":50051"}) {
    options.listen_address = address;
    options.tls = {};
    const std::string why = options.Check();
    EXPECT_THAT(why, HasSubstr(std::string("'") + address + "'"));
    EXPECT_THAT(why, HasSubstr("--tls-cert/--tls-key"));
    EXPECT_THAT(why, HasSubstr("--insecure-plaintext"));
    options.tls.insecure_plaintext = true;
    EXPECT_EQ(options.Check(), "") << address;
    options.tls = {.cert_file = "server.pem", .key_file = "server.key"};
    EXPECT_EQ(options.Check(), "") << address;
  }
  options.tls = {};
  for (const char* address : {"127.0.0.1:0", "localhost:50051", "[::1]:0", "unix:/tmp/ave.sock"}) {
    options.listen_address = address;
    EXPECT_EQ(options.Check(), "") << address;
  }
  // Start refuses before it touches the store.
  TempDir dir;
  ServerOptions wildcard = Options(dir);
  wildcard.listen_address = "0.0.0.0:0";
  auto refused = FusionServer::Start(wildcard);
  ASSERT_FALSE(refused.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(refused.status()));
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("--insecure-plaintext"));
  EXPECT_FALSE(std::filesystem::exists(dir.store()));
}

TEST(PlaintextRule, WithTheFlagTheServerServesWarnsRepeatedlyAndSaysSoInItsMetrics) {
  TempDir dir;
  ServerOptions options = Options(dir);
  options.listen_address = "0.0.0.0:0";
  options.tls.insecure_plaintext = true;
  options.plaintext_warning_period = std::chrono::milliseconds(10);
  auto server = FusionServer::Start(options);
  ASSERT_TRUE(server.ok()) << server.status();
  EXPECT_EQ(Metric((*server)->RenderMetrics(), "ave_insecure_plaintext"), 1);
  EXPECT_TRUE(AddCamera(*Loopback((*server)->port()), kAdmin, "cam-a").ok());
  // The warning at start, then one per period: wait for the third (a deadline, not a sleep).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  double warnings = 0;
  while ((warnings = Metric((*server)->RenderMetrics(), "ave_insecure_plaintext_warnings_total")) < 3 &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_GE(warnings, 3);
  server->reset();

  // With the default period (a minute) the warning thread still stops at once with the server.
  TempDir dir2;
  ServerOptions slow = Options(dir2);
  slow.listen_address = "0.0.0.0:0";
  slow.tls.insecure_plaintext = true;
  auto quiet = FusionServer::Start(slow);
  ASSERT_TRUE(quiet.ok()) << quiet.status();
  EXPECT_EQ(Metric((*quiet)->RenderMetrics(), "ave_insecure_plaintext_warnings_total"), 1);
  const auto before = std::chrono::steady_clock::now();
  quiet->reset();
  EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::seconds(30));

  // On loopback there is nothing to warn about.
  TempDir dir3;
  auto loopback = FusionServer::Start(Options(dir3));
  ASSERT_TRUE(loopback.ok()) << loopback.status();
  EXPECT_EQ(Metric((*loopback)->RenderMetrics(), "ave_insecure_plaintext"), 0);
  EXPECT_EQ(Metric((*loopback)->RenderMetrics(), "ave_insecure_plaintext_warnings_total"), 0);
}

TEST(AuthRateLimit, BadTokensFromOnePeerAreLimitedCountedAuditedAndTheWindowPasses) {
  TempDir dir;
  ServerOptions options = Options(dir);
  std::atomic<int64_t> now_ns{1000 * kSecondNs};
  options.auth_limit.max_failures = 3;
  options.auth_limit.window_ns = 60 * kSecondNs;
  options.auth_clock_ns = [&now_ns] { return now_ns.load(); };
  auto server = FusionServer::Start(options);
  ASSERT_TRUE(server.ok()) << server.status();
  auto channel = Loopback((*server)->port());
  ASSERT_TRUE(AddCamera(*channel, kAdmin, "cam-a").ok());

  // Three failures, on three services: each answered as before.
  EXPECT_EQ(AddCamera(*channel, "guess-1", "cam-x").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  now_ns += kSecondNs;
  EXPECT_EQ(Subscribe(*channel, "guess-2").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  now_ns += kSecondNs;
  EXPECT_EQ(Stream(*channel, "cam-a", "guess-3").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  // Then the peer is refused without its token being read, even the right one.
  grpc::Status limited = AddCamera(*channel, "guess-4", "cam-x");
  EXPECT_EQ(limited.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(limited.error_message(), HasSubstr("too many failed authentications from ipv4:127.0.0.1"));
  EXPECT_THAT(limited.error_message(), HasSubstr("retry in 58 s"));
  EXPECT_EQ(AddCamera(*channel, kAdmin, "cam-b").error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);

  const std::string metrics = (*server)->RenderMetrics();
  EXPECT_EQ(Metric(metrics, "ave_auth_failures_total"), 3);
  EXPECT_EQ(Metric(metrics, "ave_auth_rate_limited_total"), 2);
  EXPECT_EQ(Metric(metrics, "ave_auth_tracked_peers"), 1);

  // A window after the first failure, the right token works again; a new failure opens a new
  // window and reports the last one's counts.
  now_ns += 59 * kSecondNs;
  EXPECT_TRUE(AddCamera(*channel, kAdmin, "cam-b").ok());
  EXPECT_EQ(AddCamera(*channel, "guess-5", "cam-x").error_code(), grpc::StatusCode::UNAUTHENTICATED);
  server->reset();

  auto store = store::Store::Open(dir.store());
  ASSERT_TRUE(store.ok()) << store.status();
  auto audit = (*store)->ListAudit();
  ASSERT_TRUE(audit.ok()) << audit.status();
  std::vector<store::AuditEntry> refused, limited_rows;
  for (const store::AuditEntry& a : *audit) {
    EXPECT_THAT(a.actor + a.target + a.after_json, Not(HasSubstr("guess")));  // no presented token is kept
    if (a.action == "AuthRefused") refused.push_back(a);
    if (a.action == "AuthRateLimited") limited_rows.push_back(a);
  }
  // Five failures and two limited calls leave three rows: the first failure of each window and
  // the one that set the limit off.
  ASSERT_EQ(refused.size(), 2u);
  ASSERT_EQ(limited_rows.size(), 1u);
  const store::AuditEntry& first = refused[1];  // newest first
  EXPECT_EQ(first.actor, "unauthenticated@ipv4:127.0.0.1");
  EXPECT_THAT(first.target, HasSubstr("manage cameras"));
  EXPECT_THAT(first.after_json, HasSubstr("unknown or revoked bearer token"));
  EXPECT_THAT(limited_rows[0].target, HasSubstr("stream frames as camera 'cam-a'"));
  EXPECT_THAT(limited_rows[0].after_json, HasSubstr("\"failures\":3"));
  EXPECT_THAT(refused[0].after_json, HasSubstr("\"previous_window\":{\"failures\":3,\"rate_limited\":2}"));
}

}  // namespace
}  // namespace ave
