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

constexpr double kPi = 3.14159265358979323846;

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

// The closed part each triangle belongs to: triangles sharing a vertex index are one part.
std::vector<int> TrianglePart(const std::vector<uint32_t>& indices, size_t vertices) {
  std::vector<uint32_t> parent(vertices);
  for (size_t i = 0; i < vertices; ++i) parent[i] = static_cast<uint32_t>(i);
  auto find = [&](uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    parent[find(indices[t + 1])] = find(indices[t]);
    parent[find(indices[t + 2])] = find(indices[t]);
  }
  std::unordered_map<uint32_t, int> id;
  std::vector<int> part;
  for (size_t t = 0; t + 2 < indices.size(); t += 3) part.push_back(id.emplace(find(indices[t]), static_cast<int>(id.size())).first->second);
  return part;
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

absl::StatusOr<SimulatedFrameSet> SimulateStudioFrameSet(int frame, int cameras, std::optional<sim::StudioActor> actor) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("studio");
  if (!scenario.ok()) return scenario.status();
  if (!scenario->studio) return absl::InternalError("the studio scenario names no studio sensor");
  sim::StudioSpec spec = *scenario->studio;
  if (cameras > 0) spec.cameras = cameras;
  if (actor) spec.actor = *actor;
  SimulatedFrameSet set;
  set.t_s = frame / spec.fps;
  set.actor = spec.actor;
  set.truth_mesh = sim::StudioActorMesh(set.t_s, spec.actor);
  for (const sim::StudioCamera& cam : sim::StudioCameras(spec)) {
    const sim::EffectSet effects = scenario->EffectsForCamera(cam.id);
    set.cameras.push_back({cam.id, cam.intrinsics, cam.world_from_camera});
    const sim::StudioView view = sim::RenderStudioView(cam, effects, scenario->seed, frame, set.t_s, spec.actor);
    set.images.push_back(ToImage(view));
    set.truth_silhouettes.push_back(Mask{view.width, view.height, view.silhouette});
    set.backgrounds.push_back(ToImage(sim::RenderStudioBackground(cam, effects, scenario->seed)));
  }
  return set;
}

VoxelGrid TruthOccupancy(const VoxelGrid& lattice, const TriangleMesh& truth) {
  VoxelGrid out;
  out.voxel_m = lattice.voxel_m;
  const std::vector<Tri> tris = Triangles(truth.positions, truth.indices, truth.origin);
  if (tris.empty()) {
    out.origin_m = lattice.origin_m;
    out.size = lattice.size;
    out.occupied.assign(lattice.occupied.size(), 0);
    return out;
  }
  // The lattice over both the given grid and the truth's box.
  Eigen::AlignedBox3d box;
  for (const Tri& t : tris) box.extend(t.a), box.extend(t.b), box.extend(t.c);
  const double h = lattice.voxel_m;
  const Eigen::Vector3i lo = ((box.min() - lattice.origin_m) / h).array().floor().cast<int>().min(0);
  const Eigen::Vector3i hi = ((box.max() - lattice.origin_m) / h).array().ceil().cast<int>().max(lattice.size.array());
  out.origin_m = lattice.origin_m + h * lo.cast<double>();
  out.size = hi - lo;
  out.occupied.assign(static_cast<size_t>(out.size.x()) * out.size.y() * out.size.z(), 0);
  // Inside = inside at least one closed part, each part by the parity of its own crossings of
  // the vertical line: overlapping parts count once and a part wound inward counts as well
  // (a summed winding number would cancel it against an outward part it overlaps).
  const std::vector<int> part = TrianglePart(truth.indices, truth.positions.size());
  const int parts = part.empty() ? 0 : *std::max_element(part.begin(), part.end()) + 1;
  std::vector<std::pair<double, int>> crossings;  // height, part
  std::vector<uint8_t> odd(parts);
  for (int y = 0; y < out.size.y(); ++y) {
    for (int x = 0; x < out.size.x(); ++x) {
      const Vector3d column = out.Center(x, y, 0);
      crossings.clear();
      for (size_t i = 0; i < tris.size(); ++i) {  // where the vertical line through the column crosses the truth
        const Tri& t = tris[i];
        const Vector2d a = t.a.head<2>(), b = t.b.head<2>(), c = t.c.head<2>(), q = column.head<2>();
        const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
        if (std::abs(area) < 1e-15) continue;
        const double l0 = ((b - q).x() * (c - q).y() - (b - q).y() * (c - q).x()) / area;
        const double l1 = ((c - q).x() * (a - q).y() - (c - q).y() * (a - q).x()) / area;
        const double l2 = 1 - l0 - l1;
        if (l0 < 0 || l1 < 0 || l2 < 0) continue;
        crossings.emplace_back(l0 * t.a.z() + l1 * t.b.z() + l2 * t.c.z(), part[i]);
      }
      std::sort(crossings.begin(), crossings.end());
      std::fill(odd.begin(), odd.end(), 0);  // below every crossing: outside every part
      int inside = 0;                        // parts the point is in
      size_t next = 0;
      for (int z = 0; z < out.size.z(); ++z) {
        const double zc = out.Center(x, y, z).z();
        for (; next < crossings.size() && crossings[next].first <= zc; ++next) {
          uint8_t& o = odd[crossings[next].second];
          o ^= 1;
          inside += o ? 1 : -1;
        }
        out.occupied[out.Index(x, y, z)] = inside > 0;
      }
    }
  }
  return out;
}

double HullVolumeIoU(const VoxelGrid& hull, const TriangleMesh& truth) {
  if (truth.indices.empty()) return 0;
  const VoxelGrid t = TruthOccupancy(hull, truth);
  const Eigen::Vector3i shift = ((hull.origin_m - t.origin_m) / hull.voxel_m).array().round().cast<int>();
  int64_t inter = 0, uni = 0;
  for (int z = 0; z < t.size.z(); ++z)
    for (int y = 0; y < t.size.y(); ++y)
      for (int x = 0; x < t.size.x(); ++x) {
        const Eigen::Vector3i g = Eigen::Vector3i(x, y, z) - shift;
        const bool in_hull = (g.array() >= 0).all() && (g.array() < hull.size.array()).all() && hull.occupied[hull.Index(g.x(), g.y(), g.z())];
        const bool in_truth = t.occupied[t.Index(x, y, z)] != 0;
        inter += in_truth && in_hull;
        uni += in_truth || in_hull;
      }
  return uni == 0 ? 1.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

Mask RenderSilhouette(const StudioCameraModel& cam, const TriangleMesh& mesh) {
  const PinholeIntrinsics& k = cam.intrinsics;
  Mask m{k.width, k.height, std::vector<uint8_t>(static_cast<size_t>(k.width) * k.height, 0)};
  const Rigid3d camera_from_world = cam.world_from_camera.Inverse();
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    Eigen::Vector2d uv[3];
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d p = camera_from_world * (mesh.origin + mesh.positions[mesh.indices[3 * t + i]].cast<double>());
      uv[i] = Eigen::Vector2d(k.fx * p.x() / p.z() + k.cx, k.fy * p.y() / p.z() + k.cy);
    }
    const double area = (uv[1] - uv[0]).x() * (uv[2] - uv[0]).y() - (uv[1] - uv[0]).y() * (uv[2] - uv[0]).x();
    if (std::abs(area) < 1e-12) continue;
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({uv[0].x(), uv[1].x(), uv[2].x()}))));
    const int u1 = std::min(k.width - 1, static_cast<int>(std::floor(std::max({uv[0].x(), uv[1].x(), uv[2].x()}))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::min({uv[0].y(), uv[1].y(), uv[2].y()}))));
    const int v1 = std::min(k.height - 1, static_cast<int>(std::floor(std::max({uv[0].y(), uv[1].y(), uv[2].y()}))));
    for (int v = v0; v <= v1; ++v)
      for (int u = u0; u <= u1; ++u) {
        bool in = true;
        for (int i = 0; i < 3 && in; ++i) {
          const Eigen::Vector2d& a = uv[(i + 1) % 3];
          const Eigen::Vector2d& c = uv[(i + 2) % 3];
          in = ((c.x() - a.x()) * (v - a.y()) - (c.y() - a.y()) * (u - a.x())) / area >= 0;
        }
        if (in) m.data[static_cast<size_t>(v) * k.width + u] = 255;
      }
  }
  return m;
}

TriangleMesh UprightPrism(const Eigen::Vector2d& centre, double radius_m, double height_m, int sides, double yaw_rad) {
  TriangleMesh m;
  for (int i = 0; i < sides; ++i) {
    const double a = yaw_rad + 2 * kPi * i / sides;
    for (double z : {0.0, height_m})
      m.positions.push_back(Eigen::Vector3f(static_cast<float>(centre.x() + radius_m * std::cos(a)), static_cast<float>(centre.y() + radius_m * std::sin(a)),
                                            static_cast<float>(z)));
  }
  const uint32_t bottom = static_cast<uint32_t>(m.positions.size());
  m.positions.push_back(Eigen::Vector3f(static_cast<float>(centre.x()), static_cast<float>(centre.y()), 0));
  m.positions.push_back(Eigen::Vector3f(static_cast<float>(centre.x()), static_cast<float>(centre.y()), static_cast<float>(height_m)));
  for (int i = 0; i < sides; ++i) {  // counter-clockwise seen from outside
    const uint32_t b0 = 2 * i, t0 = b0 + 1, b1 = 2 * ((i + 1) % sides), t1 = b1 + 1;
    m.indices.insert(m.indices.end(), {b0, b1, t1, b0, t1, t0, bottom, b1, b0, bottom + 1, t0, t1});
  }
  return m;
}

std::vector<TriangleMesh> MeshParts(const TriangleMesh& mesh) {
  const std::vector<int> part = TrianglePart(mesh.indices, mesh.positions.size());
  const int parts = part.empty() ? 0 : *std::max_element(part.begin(), part.end()) + 1;
  std::vector<TriangleMesh> out(parts);
  std::vector<std::unordered_map<uint32_t, uint32_t>> remap(parts);
  for (size_t t = 0; t < part.size(); ++t) {
    TriangleMesh& m = out[part[t]];
    m.origin = mesh.origin;
    for (int i = 0; i < 3; ++i) {
      const uint32_t v = mesh.indices[3 * t + i];
      const auto [it, added] = remap[part[t]].emplace(v, static_cast<uint32_t>(m.positions.size()));
      if (added) m.positions.push_back(mesh.positions[v]);
      m.indices.push_back(it->second);
    }
  }
  return out;
}

double ChamferMm(const SurfaceMesh& mesh, const TriangleMesh& truth, int samples) {
  const std::vector<Tri> truth_tris = Triangles(truth.positions, truth.indices, truth.origin);
  const std::vector<Tri> mesh_tris = Triangles(mesh.positions_m, mesh.indices, Vector3d::Zero());
  if (truth_tris.empty() || mesh_tris.empty()) return std::numeric_limits<double>::infinity();
  std::mt19937_64 rng(7);
  std::vector<Vector3d> truth_normals;
  std::vector<Vector3d> truth_pts = SampleSurface(truth_tris, samples, rng, &truth_normals);
  // Drop samples on faces buried inside another limb part: 2 mm outside them is still inside.
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
