#include "fusion_server/core/auth_limiter.h"

#include <algorithm>

namespace ave {

std::string AuthLimiterOptions::Check() const {
  if (max_failures < 0) return "auth_limit.max_failures must be >= 0 (0 = no limit)";
  if (window_ns <= 0) return "auth_limit.window_ns must be > 0";
  if (max_peers == 0) return "auth_limit.max_peers must be > 0";
  return {};
}

std::string PeerHost(std::string_view peer) {
  const bool ip = peer.substr(0, 5) == "ipv4:" || peer.substr(0, 5) == "ipv6:";
  const size_t colon = peer.rfind(':');
  if (!ip || colon <= 4) return std::string(peer);
  // The port is the digits after the last colon; an IPv6 address without brackets keeps its own.
  const std::string_view port = peer.substr(colon + 1);
  const bool digits = !port.empty() && std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; });
  const std::string_view host = peer.substr(0, colon);
  const bool bracketed = host.find('[') != std::string_view::npos || host.find("%5B") != std::string_view::npos;
  if (!digits || (peer[3] == '6' && !bracketed)) return std::string(peer);
  return std::string(host);
}

AuthFailureLimiter::AuthFailureLimiter(AuthLimiterOptions options) : options_(options) {}

AuthFailureLimiter::Admission AuthFailureLimiter::Admit(const std::string& peer, int64_t now_ns) {
  Admission a;
  if (options_.max_failures == 0) return a;
  std::lock_guard lock(mu_);
  auto it = peers_.find(peer);
  if (it == peers_.end() || !Open(it->second, now_ns) || it->second.failures < options_.max_failures) return a;
  Entry& e = it->second;
  a.allowed = false;
  a.retry_after_ns = e.window_start_ns + options_.window_ns - now_ns;
  a.first_refusal = e.refusals == 0;
  a.failures_in_window = e.failures;
  ++e.refusals;
  return a;
}

AuthFailureLimiter::Failure AuthFailureLimiter::RecordFailure(const std::string& peer, int64_t now_ns) {
  Failure f;
  if (options_.max_failures == 0) return f;
  std::lock_guard lock(mu_);
  auto it = peers_.find(peer);
  if (it == peers_.end()) {
    MakeRoom(now_ns);
    it = peers_.emplace(peer, Entry{now_ns, 0, 0}).first;
    f.opened_window = true;
  } else if (!Open(it->second, now_ns)) {
    f.previous_failures = it->second.failures;
    f.previous_refusals = it->second.refusals;
    it->second = Entry{now_ns, 0, 0};
    f.opened_window = true;
  }
  Entry& e = it->second;
  ++e.failures;
  f.failures_in_window = e.failures;
  f.now_limited = e.failures == options_.max_failures;
  return f;
}

void AuthFailureLimiter::MakeRoom(int64_t now_ns) {
  // Sweep ended windows once a window (amortised), and whenever the table is full.
  if (peers_.size() >= options_.max_peers || now_ns - last_sweep_ns_ >= options_.window_ns) {
    last_sweep_ns_ = now_ns;
    for (auto it = peers_.begin(); it != peers_.end();) it = Open(it->second, now_ns) ? std::next(it) : peers_.erase(it);
  }
  if (peers_.size() < options_.max_peers) return;
  // Still full of open windows: forget the oldest (it is the nearest to ending anyway).
  auto oldest = std::min_element(peers_.begin(), peers_.end(), [](const auto& a, const auto& b) {
    return a.second.window_start_ns < b.second.window_start_ns;
  });
  peers_.erase(oldest);
}

size_t AuthFailureLimiter::tracked_peers() const {
  std::lock_guard lock(mu_);
  return peers_.size();
}

}  // namespace ave
