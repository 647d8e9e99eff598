#include "tests/truth/studio_truth.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/studio.h"

namespace ave::studio::testing {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5).
Vector3d ClosestOnTriangle(const Vector3d& p, const Vector3d& a, const Vector3d& b, const Vector3d& c) {
  const Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

struct Tri {
  Vector3d a, b, c;
};

std::vector<Tri> Triangles(const std::vector<Eigen::Vector3f>& positions, const std::vector<uint32_t>& indices, const Vector3d& origin) {
  std::vector<Tri> out;
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    out.push_back({origin + positions[indices[t]].cast<double>(), origin + positions[indices[t + 1]].cast<double>(),
                   origin + positions[indices[t + 2]].cast<double>()});
  }
  return out;
}

// Winding number of p along +z: signed crossings of the upward ray (+1 leaving through an
// upward-facing triangle).
int Winding(const std::vector<Tri>& tris, const Vector3d& p) {
  int w = 0;
  for (const Tri& t : tris) {
    const Vector2d a = t.a.head<2>(), b = t.b.head<2>(), c = t.c.head<2>();
    const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (std::abs(area) < 1e-15) continue;
    const Vector2d q = p.head<2>();
    const double l0 = ((b - q).x() * (c - q).y() - (b - q).y() * (c - q).x()) / area;
    const double l1 = ((c - q).x() * (a - q).y() - (c - q).y() * (a - q).x()) / area;
    const double l2 = 1 - l0 - l1;
    if (l0 < 0 || l1 < 0 || l2 < 0) continue;
    if (l0 * t.a.z() + l1 * t.b.z() + l2 * t.c.z() <= p.z()) continue;
    w += area > 0 ? 1 : -1;
  }
  return w;
}

std::vector<Vector3d> SampleSurface(const std::vector<Tri>& tris, int n, std::mt19937_64& rng, std::vector<Vector3d>* normals) {
  std::vector<double> cum;
  double total = 0;
  for (const Tri& t : tris) cum.push_back(total += 0.5 * (t.b - t.a).cross(t.c - t.a).norm());
  std::vector<Vector3d> out;
  if (total <= 0) return out;
  std::uniform_real_distribution<double> u01(0, 1);
  for (int i = 0; i < n; ++i) {
    const size_t k = std::min(cum.size() - 1, static_cast<size_t>(std::lower_bound(cum.begin(), cum.end(), u01(rng) * total) - cum.begin()));
    double r1 = u01(rng), r2 = u01(rng);
    if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
    const Tri& t = tris[k];
    out.push_back(t.a + r1 * (t.b - t.a) + r2 * (t.c - t.a));
    if (normals) normals->push_back((t.b - t.a).cross(t.c - t.a).normalized());
  }
  return out;
}

// Nearest-triangle queries through a uniform grid of triangle boxes.
class TriangleGrid {
 public:
  TriangleGrid(const std::vector<Tri>& tris, double cell) : tris_(tris), cell_(cell) {
    for (size_t i = 0; i < tris.size(); ++i) {
      const Eigen::Vector3i lo = Key(tris[i].a.cwiseMin(tris[i].b).cwiseMin(tris[i].c));
      const Eigen::Vector3i hi = Key(tris[i].a.cwiseMax(tris[i].b).cwiseMax(tris[i].c));
      for (int z = lo.z(); z <= hi.z(); ++z)
        for (int y = lo.y(); y <= hi.y(); ++y)
          for (int x = lo.x(); x <= hi.x(); ++x) cells_[Hash({x, y, z})].push_back(static_cast<int>(i));
    }
  }
  double Distance(const Vector3d& p) const {
    const Eigen::Vector3i c = Key(p);
    double best = 1e30;
    for (int r = 0; r < 64; ++r) {
      for (int z = -r; z <= r; ++z)
        for (int y = -r; y <= r; ++y)
          for (int x = -r; x <= r; ++x) {
            if (std::max({std::abs(x), std::abs(y), std::abs(z)}) != r) continue;
            const auto it = cells_.find(Hash(c + Eigen::Vector3i(x, y, z)));
            if (it == cells_.end()) continue;
            for (int i : it->second) best = std::min(best, (ClosestOnTriangle(p, tris_[i].a, tris_[i].b, tris_[i].c) - p).norm());
          }
      if (best <= r * cell_) break;  // no cell further out can hold anything closer
    }
    return best;
  }

 private:
  Eigen::Vector3i Key(const Vector3d& p) const { return (p / cell_).array().floor().cast<int>(); }
  static int64_t Hash(const Eigen::Vector3i& k) {
    return (static_cast<int64_t>(k.x()) + (1 << 20)) | ((static_cast<int64_t>(k.y()) + (1 << 20)) << 21) | ((static_cast<int64_t>(k.z()) + (1 << 20)) << 42);
  }
  const std::vector<Tri>& tris_;
  double cell_;
  std::unordered_map<int64_t, std::vector<int>> cells_;
};

Image ToImage(const sim::StudioView& v) { return Image{v.width, v.height, v.bgr}; }

}  // namespace

absl::StatusOr<SimulatedFrameSet> SimulateStudioFrameSet(int frame, int cameras) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("studio");
  if (!scenario.ok()) return scenario.status();
  if (!scenario->studio) return absl::InternalError("the studio scenario names no studio sensor");
  sim::StudioSpec spec = *scenario->studio;
  if (cameras > 0) spec.cameras = cameras;
  SimulatedFrameSet set;
  set.t_s = frame / spec.fps;
  set.truth_mesh = sim::StudioActorMesh(set.t_s);
  for (const sim::StudioCamera& cam : sim::StudioCameras(spec)) {
    const sim::EffectSet effects = scenario->EffectsForCamera(cam.id);
    set.cameras.push_back({cam.id, cam.intrinsics, cam.world_from_camera});
    const sim::StudioView view = sim::RenderStudioView(cam, effects, scenario->seed, frame, set.t_s);
    set.images.push_back(ToImage(view));
    set.truth_silhouettes.push_back(Mask{view.width, view.height, view.silhouette});
    set.backgrounds.push_back(ToImage(sim::RenderStudioBackground(cam, effects, scenario->seed)));
  }
  return set;
}

double HullVolumeIoU(const VoxelGrid& hull, const TriangleMesh& truth) {
  const std::vector<Tri> tris = Triangles(truth.positions, truth.indices, truth.origin);
  if (tris.empty()) return 0;
  // The lattice over both the hull grid and the truth's box.
  Eigen::AlignedBox3d box;
  for (const Tri& t : tris) box.extend(t.a), box.extend(t.b), box.extend(t.c);
  const double h = hull.voxel_m;
  const Eigen::Vector3i lo = ((box.min() - hull.origin_m) / h).array().floor().cast<int>().min(0);
  const Eigen::Vector3i hi = ((box.max() - hull.origin_m) / h).array().ceil().cast<int>().max(hull.size.array());
  int64_t inter = 0, uni = 0;
  std::vector<std::pair<double, int>> crossings;
  for (int y = lo.y(); y < hi.y(); ++y) {
    for (int x = lo.x(); x < hi.x(); ++x) {
      const Vector3d column = hull.origin_m + h * Vector3d(x + 0.5, y + 0.5, 0);
      crossings.clear();
      for (const Tri& t : tris) {  // where the vertical line through the column crosses the truth
        const Vector2d a = t.a.head<2>(), b = t.b.head<2>(), c = t.c.head<2>(), q = column.head<2>();
        const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
        if (std::abs(area) < 1e-15) continue;
        const double l0 = ((b - q).x() * (c - q).y() - (b - q).y() * (c - q).x()) / area;
        const double l1 = ((c - q).x() * (a - q).y() - (c - q).y() * (a - q).x()) / area;
        const double l2 = 1 - l0 - l1;
        if (l0 < 0 || l1 < 0 || l2 < 0) continue;
        crossings.emplace_back(l0 * t.a.z() + l1 * t.b.z() + l2 * t.c.z(), area > 0 ? 1 : -1);
      }
      std::sort(crossings.begin(), crossings.end());
      int above = 0;  // winding of a point below every crossing
      for (const auto& cr : crossings) above += cr.second;
      size_t next = 0;
      for (int z = lo.z(); z < hi.z(); ++z) {
        const double zc = hull.origin_m.z() + h * (z + 0.5);
        while (next < crossings.size() && crossings[next].first <= zc) above -= crossings[next++].second;
        const bool in_truth = above != 0;
        const bool in_hull = x >= 0 && y >= 0 && z >= 0 && x < hull.size.x() && y < hull.size.y() && z < hull.size.z() &&
                             hull.occupied[hull.Index(x, y, z)];
        inter += in_truth && in_hull;
        uni += in_truth || in_hull;
      }
    }
  }
  return uni == 0 ? 1.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

double ChamferMm(const SurfaceMesh& mesh, const TriangleMesh& truth, int samples) {
  const std::vector<Tri> truth_tris = Triangles(truth.positions, truth.indices, truth.origin);
  const std::vector<Tri> mesh_tris = Triangles(mesh.positions_m, mesh.indices, Vector3d::Zero());
  if (truth_tris.empty() || mesh_tris.empty()) return std::numeric_limits<double>::infinity();
  std::mt19937_64 rng(7);
  std::vector<Vector3d> truth_normals;
  std::vector<Vector3d> truth_pts = SampleSurface(truth_tris, samples, rng, &truth_normals);
  // Drop samples on faces buried inside another limb box: 2 mm outside them is still inside.
  std::vector<Vector3d> outer;
  for (size_t i = 0; i < truth_pts.size(); ++i) {
    if (Winding(truth_tris, truth_pts[i] + 0.002 * truth_normals[i]) == 0) outer.push_back(truth_pts[i]);
  }
  const std::vector<Vector3d> mesh_pts = SampleSurface(mesh_tris, samples, rng, nullptr);
  const TriangleGrid to_truth(truth_tris, 0.05), to_mesh(mesh_tris, 0.02);
  double a = 0, b = 0;
  for (const Vector3d& p : mesh_pts) a += to_truth.Distance(p);
  for (const Vector3d& p : outer) b += to_mesh.Distance(p);
  return 1000.0 * 0.5 * (a / std::max<size_t>(1, mesh_pts.size()) + b / std::max<size_t>(1, outer.size()));
}

}  // namespace ave::studio::testing
