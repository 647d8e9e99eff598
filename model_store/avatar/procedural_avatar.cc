#include "model_store/avatar/procedural_avatar.h"

#include <cmath>

#include <Eigen/Geometry>

namespace ave::avatar {
namespace {

// Appends an axis-aligned box [lo, hi] transformed by `pose` (24 vertices: flat normals), every
// vertex sampling the centre of atlas cell `cell` (row-major 4 x 4).
void AddBox(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, const Eigen::Affine3f& pose, int cell,
            AvatarFrame& frame) {
  const Eigen::Vector2f uv((cell % 4 + 0.5f) / 4.0f, (cell / 4 + 0.5f) / 4.0f);
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      Eigen::Vector3f n = Eigen::Vector3f::Zero();
      n[axis] = side ? 1.0f : -1.0f;
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const uint32_t base = static_cast<uint32_t>(frame.positions_m.size());
      for (int k = 0; k < 4; ++k) {
        Eigen::Vector3f p;
        p[axis] = side ? hi[axis] : lo[axis];
        p[u] = (k == 1 || k == 2) ? hi[u] : lo[u];
        p[v] = (k >= 2) ? hi[v] : lo[v];
        frame.positions_m.push_back(pose * p);
        frame.normals.push_back((pose.linear() * n).normalized());
        frame.uv.push_back(uv);
      }
      // (u, v) corners 0,1,2,3 wind counter-clockwise seen from +axis; flip for the -axis face.
      const uint32_t quad[2][6] = {{0, 2, 1, 0, 3, 2}, {0, 1, 2, 0, 2, 3}};
      for (uint32_t i : quad[side]) frame.indices.push_back(base + i);
    }
  }
}

}  // namespace

AvatarSequence MakeProceduralWalk(const ProceduralAvatarOptions& options, const char* name) {
  AvatarSequence seq;
  seq.name = name;
  seq.frame_period_s = options.cycle_s / options.frame_count;
  seq.stride_m = options.stride_m;
  const int side = options.atlas_side;
  std::vector<uint8_t> atlas(static_cast<size_t>(side) * side * 3, 128);
  for (int y = 0; y < side; ++y) {
    for (int x = 0; x < side; ++x) {
      const int cell = (y * 4 / side) * 4 + (x * 4 / side);
      if (cell >= static_cast<int>(kProceduralPartRgb.size())) continue;
      for (int c = 0; c < 3; ++c) atlas[(static_cast<size_t>(y) * side + x) * 3 + c] = kProceduralPartRgb[cell][c];
    }
  }
  for (int i = 0; i < options.frame_count; ++i) {
    AvatarFrame f;
    const float swing = static_cast<float>(options.swing_rad * std::sin(2.0 * M_PI * i / options.frame_count));
    for (int leg = 0; leg < 2; ++leg) {
      const float y = leg ? 0.11f : -0.11f;
      Eigen::Affine3f hip = Eigen::Affine3f::Identity();
      hip.translate(Eigen::Vector3f(0, y, 0.85f));
      hip.rotate(Eigen::AngleAxisf(leg ? swing : -swing, Eigen::Vector3f::UnitY()));
      AddBox({-0.075f, -0.075f, -0.85f}, {0.075f, 0.075f, 0.0f}, hip, 0, f);
    }
    const Eigen::Affine3f id = Eigen::Affine3f::Identity();
    AddBox({-0.125f, -0.225f, 0.85f}, {0.125f, 0.225f, 1.45f}, id, 1, f);
    AddBox({-0.11f, -0.11f, 1.5f}, {0.11f, 0.11f, 1.72f}, id, 2, f);
    AddBox({0.11f, -0.05f, 1.56f}, {0.21f, 0.05f, 1.66f}, id, 3, f);
    f.atlas_width = f.atlas_height = side;
    f.atlas_rgb = atlas;
    seq.frames.push_back(std::move(f));
  }
  return seq;
}

}  // namespace ave::avatar
