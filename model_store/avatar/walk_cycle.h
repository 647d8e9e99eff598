#pragma once
// The walk cycle of a short studio sequence (i4D §5: "only two steps ... can be recorded ... this
// short sequence can be multiplied and seamlessly extended in time"): per frame the root (the
// ground point under the actor) and the heading (direction of travel of the root) are removed,
// then the frame pair (i, j), j - i >= the shortest cycle, whose shapes differ least (symmetric
// Chamfer distance between their vertices) closes the loop: frames i..j-1 are the cycle, and
// frame j ~ frame i makes the repetition seamless. stride_m is the root's path length from i to j.
#include <string>
#include <vector>

#include <Eigen/Core>
#include "absl/status/statusor.h"

#include "model_store/avatar/avatar_sequence.h"

namespace ave::avatar {

struct WalkCycleOptions {
  double min_cycle_s = 0.8;     // shortest loop: a full walk cycle (two steps) is ~1 s, one step ~0.5 s
  int max_points = 3000;        // vertices per frame used by the shape difference (evenly thinned)
  int heading_half_window = 2;  // heading from the root's displacement over +-this many frames
  double min_travel_m = 0.01;   // below this displacement a frame keeps the neighbouring heading
  std::string Check() const;
};

struct WalkCycle {
  AvatarSequence sequence;             // frames i..j-1 in the avatar frame (avatar_sequence.h)
  int first = 0, end = 0;              // i and j
  double shape_difference_m = 0;       // Chamfer distance between frames i and j (avatar frame)
  std::vector<double> heading_rad;     // per input frame, the heading removed (from +x, counter-clockwise)
};

// The root a frame's mesh gives when none is known: the area-weighted centroid of its surface in
// x and y, on its lowest point in z (the floor under the actor).
Eigen::Vector3d GroundCentroid(const AvatarFrame& frame);

// `frames` in world coordinates (metres, z up), `roots_m` one per frame (the ground point under
// the actor), `frame_period_s` > 0. One frame gives a statue (that frame, stride 0). Fewer frames
// than the shortest cycle needs is an error naming both counts.
absl::StatusOr<WalkCycle> FindWalkCycle(const std::vector<AvatarFrame>& frames, const std::vector<Eigen::Vector3d>& roots_m,
                                        double frame_period_s, const std::string& name, const WalkCycleOptions& options);

}  // namespace ave::avatar
