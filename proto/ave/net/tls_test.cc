// Issue 14: no bearer token in clear off this host. The transport rule shared by the server and
// every client: plaintext only on loopback, unless the operator passes --insecure-plaintext.
#include "ave/net/tls.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::net {
namespace {

using ::testing::HasSubstr;

TEST(Transport, LoopbackAddressesAreRecognisedInEveryForm) {
  for (const char* a : {"127.0.0.1:50051", "127.0.0.1:0", "127.8.9.10:1", "localhost:50051", "LOCALHOST:1", "localhost",
                        "[::1]:50051", "::1", "[::ffff:127.0.0.1]:5", "unix:/tmp/ave.sock", "unix:///tmp/ave.sock",
                        "unix-abstract:ave", "dns:///localhost:50051", "dns://8.8.8.8/127.0.0.1:5", "dns:localhost:5",
                        "ipv4:127.0.0.1:5", "ipv4:127.0.0.1:5,127.0.0.2:6", "ipv6:[::1]:5"}) {
    EXPECT_TRUE(IsLoopbackAddress(a)) << a;
  }
}

TEST(Transport, WildcardOtherAddressesAndNamesAreNotLoopback) {
  for (const char* a : {"0.0.0.0:50051", "[::]:50051", "::", ":50051", "", "10.0.0.5:50051", "192.168.1.2:1",
                        "128.0.0.1:5", "[2001:db8::1]:5", "[::ffff:10.0.0.1]:5", "ave-server.ave.svc:50051",
                        "localhost.example.com:1", "127.0.0.1.example.com:1", "dns:///ave.example:1",
                        "ipv4:127.0.0.1:5,10.0.0.1:6", "ipv4:", "ipv6:[2001:db8::1]:5"}) {
    EXPECT_FALSE(IsLoopbackAddress(a)) << a;
  }
}

TEST(Transport, ServerRefusesPlaintextOffLoopbackUnlessTold) {
  TlsServerOptions plain;
  EXPECT_TRUE(CheckServerTransport("127.0.0.1:0", plain).ok());
  EXPECT_TRUE(CheckServerTransport("unix:/tmp/x", plain).ok());
  const absl::Status refused = CheckServerTransport("0.0.0.0:50051", plain);
  EXPECT_TRUE(absl::IsFailedPrecondition(refused));
  const std::string why(refused.message());
  EXPECT_THAT(why, HasSubstr("'0.0.0.0:50051'"));
  EXPECT_THAT(why, HasSubstr("--tls-cert/--tls-key"));
  EXPECT_THAT(why, HasSubstr("--insecure-plaintext"));
  EXPECT_EQ(why.find('\n'), std::string::npos);
  EXPECT_FALSE(CheckServerTransport("[::]:1", plain).ok());
  TlsServerOptions told;
  told.insecure_plaintext = true;
  EXPECT_TRUE(CheckServerTransport("0.0.0.0:50051", told).ok());
  TlsServerOptions tls;
  tls.cert_file = "server.pem";
  EXPECT_TRUE(CheckServerTransport("0.0.0.0:50051", tls).ok());
}

TEST(Transport, ClientsRefuseAPlaintextNonLoopbackTargetNamingIt) {
  auto refused = MakeChannel("10.1.2.3:50051", {});
  ASSERT_FALSE(refused.ok());
  EXPECT_TRUE(absl::IsFailedPrecondition(refused.status()));
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("'10.1.2.3:50051'"));
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("--insecure-plaintext"));
  EXPECT_THAT(std::string(refused.status().message()), HasSubstr("--tls-ca"));
  EXPECT_FALSE(MakeChannel("ave-server.ave.svc:50051", {}).ok());
  // Loopback stays as it was; the flag or TLS (here: a CA file that is then read) lets it through.
  EXPECT_TRUE(MakeChannel("127.0.0.1:50051", {}).ok());
  EXPECT_TRUE(MakeChannel("10.1.2.3:50051", {.insecure_plaintext = true}).ok());
  auto tls = MakeChannel("10.1.2.3:50051", {.ca_file = "/no/such/ca.pem"});
  EXPECT_THAT(std::string(tls.status().message()), HasSubstr("/no/such/ca.pem"));  // past the plaintext check
}

TEST(Transport, AnUnusableListenAddressIsExplainedByItsRealCause) {
  EXPECT_THAT(std::string(ExplainUnusableListenAddress("127.0.0.1:99999").message()), HasSubstr("not in 0..65535"));
  EXPECT_THAT(std::string(ExplainUnusableListenAddress("127.0.0.1").message()), HasSubstr("no port"));
  // gRPC itself would wrap 70000 to 4464 and listen there: the syntax check refuses it first.
  EXPECT_THAT(std::string(CheckListenAddressSyntax("127.0.0.1:70000").message()), HasSubstr("not in 0..65535"));
  EXPECT_THAT(std::string(CheckListenAddressSyntax("[::1]").message()), HasSubstr("no port"));
  EXPECT_TRUE(CheckListenAddressSyntax("[::1]:0").ok());
  EXPECT_TRUE(CheckListenAddressSyntax("dns:///localhost:50051").ok());
  EXPECT_TRUE(CheckListenAddressSyntax("unix:/tmp/ave.sock").ok());
  EXPECT_THAT(std::string(ExplainUnusableListenAddress("no-such-host.invalid:5000").message()),
              HasSubstr("host 'no-such-host.invalid' does not resolve"));
  // 192.0.2.1 (TEST-NET-1) is nobody's address, so not this host's.
  EXPECT_THAT(std::string(ExplainUnusableListenAddress("192.0.2.1:5000").message()),
              HasSubstr("not one of this host's"));
  // A port another socket listens on.
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(::listen(fd, 1), 0);
  socklen_t length = sizeof a;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &length), 0);
  const std::string taken = "127.0.0.1:" + std::to_string(ntohs(a.sin_port));
  const absl::Status status = ExplainUnusableListenAddress(taken);
  EXPECT_EQ(status.code(), absl::StatusCode::kUnavailable);
  EXPECT_THAT(std::string(status.message()), HasSubstr(taken));
  EXPECT_THAT(std::string(status.message()), HasSubstr("holds the port"));
  ::close(fd);
}

}  // namespace
}  // namespace ave::net
