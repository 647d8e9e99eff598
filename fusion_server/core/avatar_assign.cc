#include "fusion_server/core/avatar_assign.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

namespace ave {
namespace {

double WrapPi(double a) {  // (-pi, pi]
  a = std::remainder(a, 2.0 * M_PI);
  return a <= -M_PI ? a + 2.0 * M_PI : a;
}

}  // namespace

std::string AvatarAssignOptions::Check() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(standing_speed_mps)) return "standing_speed_mps must be finite and > 0";
  if (!positive(heading_time_constant_s)) return "heading_time_constant_s must be finite and > 0";
  if (!positive(max_turn_rate_radps)) return "max_turn_rate_radps must be finite and > 0";
  if (!positive(jump_m)) return "jump_m must be finite and > 0";
  return {};
}

int AvatarFrameAt(double phase_cycles, int64_t frame_count) {
  if (frame_count <= 1 || !std::isfinite(phase_cycles)) return 0;
  const double wrapped = phase_cycles - std::floor(phase_cycles);
  return static_cast<int>(std::min<int64_t>(frame_count - 1, static_cast<int64_t>(wrapped * frame_count)));
}

AvatarAssigner::AvatarAssigner(AvatarAssignOptions options) : options_(options) {}

void AvatarAssigner::SetSequences(std::vector<AvatarSequenceInfo> sequences) {
  std::sort(sequences.begin(), sequences.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  sequences_ = std::move(sequences);
  for (auto& [id, person] : people_) {
    const AvatarSequenceInfo* s = SequenceFor(id, person.pose.sequence);
    person.pose.sequence = s ? s->name : std::string();
    person.pose.sequence_version = s ? s->version : 0;
  }
}

const AvatarSequenceInfo* AvatarAssigner::SequenceFor(uint64_t object_id, const std::string& current) const {
  if (sequences_.empty()) return nullptr;
  for (const auto& s : sequences_)
    if (s.name == current) return &s;
  return &sequences_[object_id % sequences_.size()];
}

const AvatarPose& AvatarAssigner::Update(uint64_t object_id, const Eigen::Vector2d& position_xy, int64_t t_ns,
                                         double initial_heading_rad) {
  auto [it, inserted] = people_.try_emplace(object_id);
  Person& p = it->second;
  const AvatarSequenceInfo* seq = SequenceFor(object_id, p.pose.sequence);
  p.pose.sequence = seq ? seq->name : std::string();
  p.pose.sequence_version = seq ? seq->version : 0;
  if (inserted || !position_xy.allFinite()) {
    if (position_xy.allFinite()) p.position = position_xy;
    p.t_ns = t_ns;
    if (inserted) p.pose.heading_rad = std::isfinite(initial_heading_rad) ? WrapPi(initial_heading_rad) : 0.0;
    return p.pose;
  }
  const Eigen::Vector2d step = position_xy - p.position;
  const double step_m = step.norm();
  if (step_m > options_.jump_m) {
    // Re-placed: the track jumped (re-association, merge, gap); walking there would slide.
    p.position = position_xy;
    p.velocity.setZero();
    p.t_ns = t_ns;
    ++p.pose.placement;
    return p.pose;
  }
  p.position = position_xy;
  const bool later = t_ns > p.t_ns;
  const double dt_s = later ? (t_ns - p.t_ns) * 1e-9 : 0.0;
  if (later) {  // the same instant from another sensor moves the avatar without a velocity
    p.t_ns = t_ns;
    const double alpha = 1.0 - std::exp(-dt_s / options_.heading_time_constant_s);
    p.velocity += alpha * (step / dt_s - p.velocity);
  }
  // Standing: the fused position jitters; neither phase nor heading follow the jitter.
  if (p.velocity.norm() < options_.standing_speed_mps) return p.pose;
  if (seq && seq->frame_count > 1 && seq->stride_m > 0) {
    p.pose.walked_m += step_m;
    p.pose.phase_cycles += step_m / seq->stride_m;
    p.pose.phase_cycles -= std::floor(p.pose.phase_cycles);
  }
  if (!later) return p.pose;
  const double target = std::atan2(p.velocity.y(), p.velocity.x());
  const double turn = WrapPi(target - p.pose.heading_rad);
  const double max_turn = options_.max_turn_rate_radps * dt_s;
  p.pose.heading_rad = WrapPi(p.pose.heading_rad + std::clamp(turn, -max_turn, max_turn));
  return p.pose;
}

const AvatarPose* AvatarAssigner::Find(uint64_t object_id) const {
  auto it = people_.find(object_id);
  return it == people_.end() ? nullptr : &it->second.pose;
}

void AvatarAssigner::Retain(const std::vector<uint64_t>& live_ids) {
  const std::unordered_set<uint64_t> live(live_ids.begin(), live_ids.end());
  for (auto it = people_.begin(); it != people_.end();) it = live.count(it->first) ? std::next(it) : people_.erase(it);
}

}  // namespace ave
