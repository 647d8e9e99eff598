#include "viewer_client/render/passes/dynamic_models.h"

#include <cmath>
#include <cstring>
#include <string>

namespace ave::viewer::internal {
namespace {

// Standing models (issue 7): faces wound counter-clockwise from outside, flat normals.
void AppendModelVertices(const DynamicModel& m, std::vector<Vertex>& out) {
  const double c = std::cos(m.heading_rad), s = std::sin(m.heading_rad);
  const Eigen::Vector3d ax(c, s, 0), ay(-s, c, 0), az(0, 0, 1);
  auto quad = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& cc,
                  const Eigen::Vector3d& d, const Eigen::Vector3d& outward) {
    const Eigen::Vector3f n = outward.normalized().cast<float>();
    auto make = [&](const Eigen::Vector3d& p) { return MakeVertex(p.cast<float>(), n, m.color); };
    AppendOrientedTriangle(a, b, cc, outward, out, make);
    AppendOrientedTriangle(a, cc, d, outward, out, make);
  };
  const double height = m.size.z();
  switch (m.shape) {
    case ModelShape::kCuboid: {
      const Eigen::Vector3d hx = 0.5 * m.size.x() * ax, hy = 0.5 * m.size.y() * ay, h = height * az;
      auto corner = [&](int sx, int sy, int sz) -> Eigen::Vector3d { return m.base + sx * hx + sy * hy + sz * h; };
      quad(corner(-1, -1, 0), corner(1, -1, 0), corner(1, -1, 1), corner(-1, -1, 1), -ay);
      quad(corner(1, -1, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, -1, 1), ax);
      quad(corner(1, 1, 0), corner(-1, 1, 0), corner(-1, 1, 1), corner(1, 1, 1), ay);
      quad(corner(-1, 1, 0), corner(-1, -1, 0), corner(-1, -1, 1), corner(-1, 1, 1), -ax);
      quad(corner(-1, -1, 1), corner(1, -1, 1), corner(1, 1, 1), corner(-1, 1, 1), az);
      break;
    }
    case ModelShape::kCylinder: {
      constexpr int kSides = 16;
      const double r = 0.5 * m.size.y();
      const Eigen::Vector3d top = m.base + height * az;
      for (int k = 0; k < kSides; ++k) {
        const double a0 = 2 * M_PI * k / kSides, a1 = 2 * M_PI * (k + 1) / kSides;
        const Eigen::Vector3d d0(std::cos(a0), std::sin(a0), 0), d1(std::cos(a1), std::sin(a1), 0);
        quad(m.base + r * d0, m.base + r * d1, top + r * d1, top + r * d0, d0 + d1);
        const Eigen::Vector3f n = Eigen::Vector3f::UnitZ();
        auto make = [&](const Eigen::Vector3d& p) { return MakeVertex(p.cast<float>(), n, m.color); };
        AppendOrientedTriangle(top, top + r * d0, top + r * d1, az, out, make);
      }
      break;
    }
    case ModelShape::kBillboard: {
      const double w = 0.5 * m.size.y();
      for (const Eigen::Vector3d& across : {ay, ax}) {
        const Eigen::Vector3d normal = across.cross(az);
        const Eigen::Vector3d a = m.base - w * across, b = m.base + w * across;
        quad(a, b, b + height * az, a + height * az, normal);   // front
        quad(a, b, b + height * az, a + height * az, -normal);  // back (culled from the front)
      }
      break;
    }
  }
}

}  // namespace

absl::Status DynamicModels::Set(const std::vector<DynamicModel>& models) {
  std::vector<Vertex> vertices;
  vertices.reserve(models.size() * 30);
  Bounds bounds;
  std::vector<Bounds> per_model(models.size());
  for (size_t k = 0; k < models.size(); ++k) {
    const DynamicModel& m = models[k];
    if (!m.base.allFinite() || !std::isfinite(m.heading_rad) || !m.size.allFinite() || !m.color.allFinite() ||
        (m.size.array() <= 0).any()) {
      return absl::InvalidArgumentError("SetDynamicObjects: model " + std::to_string(k) +
                                        " needs finite values and a positive size");
    }
    AppendModelVertices(m, vertices);
    // A box around any heading: half the diagonal of the footprint is below (length + width) / 2.
    const double reach = 0.5 * (m.size.x() + m.size.y());
    per_model[k].Add(m.base - Eigen::Vector3d(reach, reach, 0));
    per_model[k].Add(m.base + Eigen::Vector3d(reach, reach, m.size.z()));
    bounds.Add(m.base - Eigen::Vector3d(m.size.x() + m.size.y(), m.size.x() + m.size.y(), 0));
    bounds.Add(m.base + Eigen::Vector3d(m.size.x() + m.size.y(), m.size.x() + m.size.y(), m.size.z()));
  }
  const bool same = vertices.size() == vertices_.size() &&
                    (vertices.empty() ||
                     std::memcmp(vertices.data(), vertices_.data(), vertices.size() * sizeof(Vertex)) == 0);
  if (same) return absl::OkStatus();
  mesh_.Upload(vertices, GL_DYNAMIC_DRAW);
  vertices_ = std::move(vertices);
  own_bounds_ = bounds;
  own_model_bounds_ = std::move(per_model);
  MergeBounds();
  return CheckGl("SetDynamicObjects");
}

void DynamicModels::SetAvatarBounds(const std::vector<Bounds>& avatar_bounds) {
  avatar_bounds_ = avatar_bounds;
  MergeBounds();
}

void DynamicModels::MergeBounds() {
  bounds_ = own_bounds_;
  model_bounds_ = own_model_bounds_;
  for (const Bounds& b : avatar_bounds_) {
    bounds_.Add(b.lo);
    bounds_.Add(b.hi);
    model_bounds_.push_back(b);
  }
  ++version_;
}

void DynamicModels::Draw() const { mesh_.Draw(GL_TRIANGLES); }

}  // namespace ave::viewer::internal
