#pragma once
// Which tracked person gets which avatar, and how it is posed (i4D §5, issue 17). Pure: no gRPC,
// no locking (SceneState holds it under its mutex).
//
// The paper places each studio avatar so that "the center point of the feet follows the
// trajectory" and turns it "in the proper direction ... from the trajectory". Per person object:
// - sequence: one of the stored sequences, chosen by object id (stable for the object's life);
// - heading: the direction of a smoothed velocity (exponential, time constant
//   heading_time_constant_s) turned towards at most max_turn_rate_radps; while the smoothed
//   speed is below standing_speed_mps the heading holds, so a person standing still (whose fused
//   position jitters) neither spins nor flips;
// - phase: cycles of the walk, advanced by distance walked / the sequence's stride while walking
//   (not standing), so the feet do not slide whatever the track's speed; a one-frame sequence
//   (or stride 0) stays at phase 0;
// - a move longer than jump_m between two updates (a re-association, a merge, a gap) re-places
//   the avatar: no distance walked, velocity forgotten, heading kept, and `placement` counts up so
//   viewers do not interpolate through walls between the old and new place.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ave {

struct AvatarAssignOptions {
  double standing_speed_mps = 0.35;      // below: standing, heading holds
  double heading_time_constant_s = 0.6;  // velocity smoothing
  double max_turn_rate_radps = 4.0;      // a reversal turns round in ~0.8 s, not in one update
  double jump_m = 3.0;                   // a longer move between updates re-places the avatar

  std::string Check() const;  // empty when valid, else the field and why
};

// What SceneState needs of a stored sequence (store::AvatarSequenceRecord's summary).
struct AvatarSequenceInfo {
  std::string name;
  int64_t version = 0;
  int64_t frame_count = 0;
  double stride_m = 0;
};

struct AvatarPose {
  std::string sequence;       // empty: no sequence stored, draw the box/cylinder model
  int64_t sequence_version = 0;
  double phase_cycles = 0;    // [0, 1): frame = floor(phase * frame_count)
  double heading_rad = 0;     // avatar +x from east, counter-clockwise
  uint32_t placement = 0;     // bumped on every re-placement (jump)
  double walked_m = 0;        // total distance walked (for tests and logs)
};

class AvatarAssigner {
 public:
  explicit AvatarAssigner(AvatarAssignOptions options = {});

  // The sequences people may get (sorted by name here). Objects keep theirs while it exists.
  void SetSequences(std::vector<AvatarSequenceInfo> sequences);
  const std::vector<AvatarSequenceInfo>& sequences() const { return sequences_; }

  // Folds in a person's ground position at t_ns (server clock, world/local metres). The first
  // update places the avatar with `initial_heading_rad` (e.g. the fused object's motion heading).
  // Updates with t_ns not after the previous one move the avatar without changing its velocity.
  const AvatarPose& Update(uint64_t object_id, const Eigen::Vector2d& position_xy, int64_t t_ns,
                           double initial_heading_rad = 0.0);
  // nullptr when the object has no avatar state.
  const AvatarPose* Find(uint64_t object_id) const;
  // Forgets every object not in `live_ids` (sorted or not).
  void Retain(const std::vector<uint64_t>& live_ids);
  size_t size() const { return people_.size(); }

 private:
  struct Person {
    AvatarPose pose;
    Eigen::Vector2d position = Eigen::Vector2d::Zero();
    Eigen::Vector2d velocity = Eigen::Vector2d::Zero();  // smoothed, m/s
    int64_t t_ns = 0;
  };
  const AvatarSequenceInfo* SequenceFor(uint64_t object_id, const std::string& current) const;
  AvatarAssignOptions options_;
  std::vector<AvatarSequenceInfo> sequences_;
  std::map<uint64_t, Person> people_;
};

// The frame of a sequence of `frame_count` frames to draw at `phase_cycles` (any real; wrapped).
int AvatarFrameAt(double phase_cycles, int64_t frame_count);

}  // namespace ave
