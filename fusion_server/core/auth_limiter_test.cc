// Issue 14: failed authentications limited per peer, with an injected clock.
#include "fusion_server/core/auth_limiter.h"

#include <gtest/gtest.h>

namespace ave {
namespace {

constexpr int64_t kSecond = 1'000'000'000;

AuthLimiterOptions Options(int max_failures, size_t max_peers = 100) {
  AuthLimiterOptions o;
  o.max_failures = max_failures;
  o.window_ns = 60 * kSecond;
  o.max_peers = max_peers;
  return o;
}

TEST(AuthLimiter, PeerIsRefusedAfterMaxFailuresUntilItsWindowEnds) {
  AuthFailureLimiter limiter(Options(3));
  const std::string peer = "ipv4:10.0.0.5";
  int64_t t = 1000 * kSecond;
  for (int i = 1; i <= 3; ++i) {
    ASSERT_TRUE(limiter.Admit(peer, t).allowed) << i;
    const AuthFailureLimiter::Failure f = limiter.RecordFailure(peer, t);
    EXPECT_EQ(f.failures_in_window, i);
    EXPECT_EQ(f.opened_window, i == 1);
    EXPECT_EQ(f.now_limited, i == 3);
    t += kSecond;
  }
  // Window opened at 1000 s; now 1003 s: refused for the 57 s left, first refusal flagged once.
  AuthFailureLimiter::Admission a = limiter.Admit(peer, t);
  EXPECT_FALSE(a.allowed);
  EXPECT_EQ(a.retry_after_ns, 57 * kSecond);
  EXPECT_TRUE(a.first_refusal);
  EXPECT_EQ(a.failures_in_window, 3);
  a = limiter.Admit(peer, 1059 * kSecond);
  EXPECT_FALSE(a.allowed);
  EXPECT_FALSE(a.first_refusal);
  EXPECT_EQ(a.retry_after_ns, kSecond);
  // Another peer is not affected.
  EXPECT_TRUE(limiter.Admit("ipv4:10.0.0.6", t).allowed);
  // The window has passed: admitted; the next failure opens a new window and reports the last one.
  EXPECT_TRUE(limiter.Admit(peer, 1060 * kSecond).allowed);
  const AuthFailureLimiter::Failure f = limiter.RecordFailure(peer, 1060 * kSecond);
  EXPECT_TRUE(f.opened_window);
  EXPECT_EQ(f.failures_in_window, 1);
  EXPECT_EQ(f.previous_failures, 3);
  EXPECT_EQ(f.previous_refusals, 2);
  EXPECT_TRUE(limiter.Admit(peer, 1060 * kSecond).allowed);
}

TEST(AuthLimiter, FailuresSpreadOverWindowsAreNotLimited) {
  AuthFailureLimiter limiter(Options(3));
  for (int i = 0; i < 10; ++i) {
    const int64_t t = i * 31 * kSecond;  // two failures per 60 s window at most
    ASSERT_TRUE(limiter.Admit("p", t).allowed) << i;
    limiter.RecordFailure("p", t);
  }
}

TEST(AuthLimiter, ZeroMaxFailuresMeansNoLimitAndNoTracking) {
  AuthFailureLimiter limiter(Options(0));
  for (int i = 0; i < 100; ++i) {
    EXPECT_TRUE(limiter.Admit("p", 0).allowed);
    limiter.RecordFailure("p", 0);
  }
  EXPECT_EQ(limiter.tracked_peers(), 0u);
}

TEST(AuthLimiter, MemoryIsBoundedByMaxPeersAndEndedWindowsAreSwept) {
  AuthFailureLimiter limiter(Options(2, /*max_peers=*/8));
  for (int i = 0; i < 1000; ++i) limiter.RecordFailure("ipv4:10.0." + std::to_string(i), i);
  EXPECT_EQ(limiter.tracked_peers(), 8u);
  // The newest peers are the ones kept: the last one is still counted.
  limiter.RecordFailure("ipv4:10.0.999", 1000);
  EXPECT_FALSE(limiter.Admit("ipv4:10.0.999", 1001).allowed);
  // A window later, one new failure sweeps every ended window.
  limiter.RecordFailure("ipv4:10.1.0", 2 * 60 * kSecond);
  EXPECT_EQ(limiter.tracked_peers(), 1u);
}

TEST(AuthLimiter, PeerHostDropsThePortOnly) {
  EXPECT_EQ(PeerHost("ipv4:10.0.0.5:41234"), "ipv4:10.0.0.5");
  EXPECT_EQ(PeerHost("ipv4:127.0.0.1:1"), "ipv4:127.0.0.1");
  EXPECT_EQ(PeerHost("ipv6:[::1]:5"), "ipv6:[::1]");
  EXPECT_EQ(PeerHost("ipv6:%5B::1%5D:5"), "ipv6:%5B::1%5D");
  EXPECT_EQ(PeerHost("ipv6:2001:db8::1"), "ipv6:2001:db8::1");  // no brackets: no port to drop
  EXPECT_EQ(PeerHost("ipv4:10.0.0.5"), "ipv4:10.0.0.5");
  EXPECT_EQ(PeerHost("unix:/tmp/ave.sock"), "unix:/tmp/ave.sock");
  EXPECT_EQ(PeerHost(""), "");
}

TEST(AuthLimiter, OptionsCheckNamesTheField) {
  AuthLimiterOptions o;
  EXPECT_EQ(o.Check(), "");
  o.window_ns = 0;
  EXPECT_NE(o.Check().find("window_ns"), std::string::npos);
  o = {};
  o.max_failures = -1;
  EXPECT_NE(o.Check().find("max_failures"), std::string::npos);
  o = {};
  o.max_peers = 0;
  EXPECT_NE(o.Check().find("max_peers"), std::string::npos);
}

}  // namespace
}  // namespace ave
