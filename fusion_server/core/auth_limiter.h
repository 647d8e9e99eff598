#pragma once
// Failed authentications limited per peer (issue 14). Pure: no gRPC, no clock of its own (the
// caller passes the time), so tests drive it with an injected clock.
//
// Each peer address gets a window that opens at its first failure and lasts `window_ns`; after
// `max_failures` failures inside it, the peer is refused outright (without looking at the token it
// presents, so a guess that happens to be right teaches it nothing) until the window ends. Then
// the next failure opens a new window. At most 2 x max_failures guesses fit in any window-long span.
//
// Memory is bounded: at most `max_peers` peers are tracked; entries whose window has ended are
// swept once a window, and when the table is full the entry with the oldest window is dropped.
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

namespace ave {

struct AuthLimiterOptions {
  int max_failures = 10;                  // failed authentications per peer per window; 0 = no limit
  int64_t window_ns = 60'000'000'000;     // 1 minute
  size_t max_peers = 10'000;              // peers tracked at once (about 100 bytes each)

  // Empty when usable, else names the bad field.
  std::string Check() const;
};

// The peer's address without its port: "ipv4:10.0.0.5:41234" -> "ipv4:10.0.0.5",
// "ipv6:[::1]:5" -> "ipv6:[::1]"; anything else ("unix:...", "") is kept whole.
std::string PeerHost(std::string_view grpc_peer);

class AuthFailureLimiter {
 public:
  explicit AuthFailureLimiter(AuthLimiterOptions options = {});

  struct Admission {
    bool allowed = true;
    int64_t retry_after_ns = 0;       // when refused: until the peer's window ends
    bool first_refusal = false;       // the first refusal of this peer in this window (log it once)
    int failures_in_window = 0;
  };
  // Whether `peer` may try to authenticate now. A refusal is counted against the window.
  Admission Admit(const std::string& peer, int64_t now_ns);

  struct Failure {
    bool opened_window = false;     // the first failure of a new window (audit it)
    bool now_limited = false;       // this failure used the window's last allowance (audit it)
    int failures_in_window = 0;
    // The peer's previous window, when it opened this one: failures and refusals seen there.
    int previous_failures = 0;
    int64_t previous_refusals = 0;
  };
  // Records a failed authentication by `peer`.
  Failure RecordFailure(const std::string& peer, int64_t now_ns);

  size_t tracked_peers() const;
  const AuthLimiterOptions& options() const { return options_; }

 private:
  struct Entry {
    int64_t window_start_ns = 0;
    int failures = 0;
    int64_t refusals = 0;
  };
  bool Open(const Entry& e, int64_t now_ns) const { return now_ns - e.window_start_ns < options_.window_ns; }
  void MakeRoom(int64_t now_ns);  // requires mu_

  const AuthLimiterOptions options_;
  mutable std::mutex mu_;
  std::unordered_map<std::string, Entry> peers_;
  int64_t last_sweep_ns_ = 0;
};

}  // namespace ave
