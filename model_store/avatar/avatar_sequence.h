#pragma once
// An avatar sequence (i4D §5): one seamless walk cycle of textured meshes reconstructed in the
// studio (model_store/studio), held by the store and drawn by viewers on every tracked person.
//
// The contract between the studio (which makes it) and the server and viewers (which use it):
// - Avatar frame: metres, z up, foot centre on the floor at the origin, walking along +x. The
//   root translation is removed per frame, so playing frames[0..n) and then frames[0] again is
//   seamless in shape and in place; an avatar walking `stride_m` per cycle advances its phase by
//   distance walked / stride_m cycles (foot placement does not slide).
// - Every frame has its own mesh and its own texture atlas (vertices do not correspond between
//   frames: the visual hull is re-meshed per frame set).
// - Texture: per-vertex uv into the frame's atlas (RGB8, row-major, top row first, u to the
//   right, v down, both in [0, 1]). A vertex shared by triangles textured from different
//   atlas charts is duplicated by the studio, so uv is strictly per vertex.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ave::avatar {

struct AvatarFrame {
  std::vector<Eigen::Vector3f> positions_m;  // avatar frame (see above)
  std::vector<Eigen::Vector3f> normals;      // unit, one per position
  std::vector<Eigen::Vector2f> uv;           // one per position, into this frame's atlas
  std::vector<uint32_t> indices;             // three per triangle, counter-clockwise outward
  int atlas_width = 0;
  int atlas_height = 0;
  std::vector<uint8_t> atlas_rgb;  // atlas_width * atlas_height * 3 bytes
};

struct AvatarSequence {
  std::string name;             // e.g. "studio-walk"; unique in the store
  double frame_period_s = 0.0;  // capture period of the frames, seconds (> 0)
  double stride_m = 0.0;        // distance the actor walked over one cycle (> 0 for a walk)
  std::vector<AvatarFrame> frames;  // one cycle; at least one frame (one frame = a statue)

  // Natural walking speed of the sequence, m/s: stride over cycle time.
  double SpeedMps() const {
    return frames.empty() || frame_period_s <= 0.0
               ? 0.0
               : stride_m / (frame_period_s * static_cast<double>(frames.size()));
  }
};

}  // namespace ave::avatar
