#include "sensor_agent/sim/sim_camera.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>

#include "sensor_agent/sim/camera_effects.h"

namespace ave::sim {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector3f;

constexpr uint32_t kNoTriangle = std::numeric_limits<uint32_t>::max();

// What the shading pass needs of a triangle; the position comes from the depth buffer.
struct Surface {
  SurfaceMaterial material = SurfaceMaterial::kTerrain;
  PixelClass cls = PixelClass::kTerrain;
  uint32_t object_id = kGroundId;
  int32_t building = -1;                  // index into the campus's buildings, or -1
  Vector3f normal = Vector3f::UnitZ();    // unit, local frame, outward
  Vector3f color = Vector3f::Zero();      // movers, trees, static objects: rgb in [0, 1]
  // Ground triangles: false when every point of the triangle (with a 0.5 m margin) lies farther
  // than each road's half width from it, i.e. RoadAt is empty there (issue 19: the road search
  // was 5 % of a moving camera's render).
  bool may_be_road = true;
};

// Distance from p to the segment a-b (2D).
double SegmentDistance(const Vector2d& p, const Vector2d& a, const Vector2d& b) {
  const Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

// Whether any point within `radius` of `centre` may lie on a road of the campus (conservative).
bool MayBeRoad(const scene::SyntheticCampus& campus, const Vector2d& centre, double radius) {
  for (const scene::Road& road : campus.roads) {
    for (size_t i = 0; i + 1 < road.points_m.size(); ++i) {
      if (SegmentDistance(centre, road.points_m[i], road.points_m[i + 1]) <= road.half_width_m + radius) return true;
    }
    if (road.points_m.size() == 1 && (road.points_m[0] - centre).norm() <= road.half_width_m + radius) return true;
  }
  return false;
}

// One building part's own frame, for window grids and roof edges.
struct PartLook {
  scene::PrimitiveKind kind = scene::PrimitiveKind::kBox;
  Vector2d center = Vector2d::Zero();
  double cos_yaw = 1, sin_yaw = 0;
  Vector2d half_size = Vector2d::Ones();
  double eave_z = 0;  // walls end here (flat roofs carry a 0.9 m parapet below it)

  Vector2d ToPart(const Vector3d& p) const {
    const double dx = p.x() - center.x(), dy = p.y() - center.y();
    return {cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy};
  }
  // Distance outside the footprint (<= 0 inside), metres.
  double Outside(const Vector3d& p) const {
    const Vector2d q = ToPart(p);
    if (kind == scene::PrimitiveKind::kCylinder || kind == scene::PrimitiveKind::kDome) {
      return (q.cwiseQuotient(half_size).norm() - 1.0) * half_size.minCoeff();
    }
    return std::max(std::abs(q.x()) - half_size.x(), std::abs(q.y()) - half_size.y());
  }
};

// A building's parts and palette.
struct BuildingLook {
  std::vector<PartLook> parts;
  double ground_z = 0;  // the base is sunk 0.5 m below the lowest ground (campus.cc)
  Vector3f wall_color, roof_color;

  // The part a surface point belongs to (the one it lies closest inside or on).
  const PartLook& PartAt(const Vector3d& p) const {
    size_t best = 0;
    double best_outside = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < parts.size(); ++i) {
      const double o = parts[i].Outside(p);
      if (std::abs(o) < best_outside) {
        best_outside = std::abs(o);
        best = i;
      }
    }
    return parts[best];
  }
};

// ---- Deterministic procedural noise ---------------------------------------------------------

// The noise functions are forced inline: the shading of every pixel calls them up to 16 times
// (issue 19, the backpack camera's render; the same operations, so the same bits).
#define AVE_SIM_INLINE [[gnu::always_inline]] inline

AVE_SIM_INLINE uint32_t Hash(int64_t x, int64_t y, uint32_t seed) {
  // Lattice coordinates folded with odd constants, then a xorshift-multiply finaliser
  // (wrapping arithmetic on purpose).
  uint32_t h = static_cast<uint32_t>(x) * 0x8da6b343u + static_cast<uint32_t>(y) * 0xd8163841u + seed * 0xcb1ab31fu;
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  h *= 0x297a2d39u;
  h ^= h >> 15;
  return h;
}

AVE_SIM_INLINE float Hash01(int64_t x, int64_t y, uint32_t seed) { return static_cast<float>(Hash(x, y, seed) >> 8) * (1.0f / 16777216.0f); }

// Value noise in [0, 1] with a C1 (smoothstep) blend; one lattice cell per unit of x, y.
AVE_SIM_INLINE float ValueNoise(double x, double y, uint32_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy);
  const auto tx = static_cast<float>(x - fx), ty = static_cast<float>(y - fy);
  const float sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty);
  const float a = Hash01(ix, iy, seed), b = Hash01(ix + 1, iy, seed);
  const float c = Hash01(ix, iy + 1, seed), d = Hash01(ix + 1, iy + 1, seed);
  return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy;
}

// 1 while a pattern of `wavelength_m` is well resolved by a pixel of `footprint_m`, falling to 0
// once it would alias; the caller then shows the pattern's mean instead.
float Resolved(double footprint_m, double wavelength_m) {
  return static_cast<float>(std::clamp(1.5 - 2.0 * footprint_m / wavelength_m, 0.0, 1.0));
}

// Noise of `wavelength_m` at p, faded to its mean 0.5 where it would alias.
AVE_SIM_INLINE float Octave(const Vector2d& p, double wavelength_m, uint32_t seed, double footprint_m) {
  const float r = Resolved(footprint_m, wavelength_m);
  if (r <= 0) return 0.5f;
  return 0.5f + r * (ValueNoise(p.x() / wavelength_m, p.y() / wavelength_m, seed) - 0.5f);
}

Vector3f Mix(const Vector3f& a, const Vector3f& b, float t) { return a + t * (b - a); }

float SmoothStep(float e0, float e1, float x) {
  const float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

// ---- Materials (rgb in [0, 1], before sun shading) --------------------------------------------

Vector3f Grass(const Vector2d& p, double footprint_m) {
  const float n = 0.55f * Octave(p, 2.5, 11, footprint_m) + 0.30f * Octave(p, 0.9, 12, footprint_m) +
                  0.15f * Octave(p, 0.45, 13, footprint_m);
  const Vector3f c = Mix(Vector3f(0.13f, 0.30f, 0.08f), Vector3f(0.42f, 0.60f, 0.20f), n);
  const float dry = SmoothStep(0.55f, 0.85f, ValueNoise(p.x() / 14.0, p.y() / 14.0, 14));
  return Mix(c, Vector3f(0.56f, 0.55f, 0.30f), 0.45f * dry);
}

// `may_be_road` false: the caller knows p lies farther than any road's half width from every road
// (Surface::may_be_road), where RoadAt would find nothing; the same result without its search.
Vector3f Ground(const scene::SyntheticCampus& campus, const Vector2d& p, double footprint_m, bool may_be_road = true) {
  if (!may_be_road) return Grass(p, footprint_m);
  const std::optional<scene::RoadPoint> road = campus.RoadAt(p.x(), p.y());
  if (!road) return Grass(p, footprint_m);
  const float g = 0.30f + 0.08f * (Octave(p, 0.6, 21, footprint_m) - 0.5f) + 0.08f * (Octave(p, 5.0, 22, footprint_m) - 0.5f);
  const Vector3f asphalt(g, g, 1.03f * g);
  if (road->crossing) return asphalt;  // the crossing carries no markings
  const double hw = road->half_width_m, across = road->across_m, along = road->along_m;
  if (across > hw - 0.25) return Vector3f(0.64f, 0.63f, 0.60f);  // concrete kerb
  // Lines 0.15 m wide: a solid edge line inside each kerb, 3 m dashes every 6 m on the centre.
  // Where a pixel is wider than the line, paint only its covered share (keeps distant lines calm).
  const float coverage = static_cast<float>(std::min(1.0, 0.15 / std::max(footprint_m, 1e-6)));
  const bool edge_line = across > hw - 0.55 && across < hw - 0.40;
  const bool centre_dash = across < 0.075 && std::fmod(std::abs(along), 6.0) < 3.0;
  return edge_line || centre_dash ? Mix(asphalt, Vector3f(0.92f, 0.92f, 0.88f), coverage) : asphalt;
}

Vector3f Wall(const BuildingLook& look, int32_t building, const Vector3d& p, const Vector3f& n, double footprint_m) {
  const PartLook& b = look.PartAt(p);
  const Vector2d q = b.ToPart(p);
  const double bx = q.x(), by = q.y();
  const double n_along_x = b.cos_yaw * n.x() + b.sin_yaw * n.y();
  const bool round = b.kind == scene::PrimitiveKind::kCylinder || b.kind == scene::PrimitiveKind::kDome;
  const bool x_face = std::abs(n_along_x) > 0.7;  // the face's normal is the part's +-x axis
  double along = x_face ? by + b.half_size.y() : bx + b.half_size.x();
  double length = 2 * (x_face ? b.half_size.y() : b.half_size.x());
  if (round) {  // unrolled around the circumference
    const double r = 0.5 * (b.half_size.x() + b.half_size.y());
    along = (std::atan2(by / b.half_size.y(), bx / b.half_size.x()) + M_PI) * r;
    length = 2 * M_PI * r;
  }
  const double h = p.z() - look.ground_z;
  const uint32_t face = round ? 0u : (x_face ? 0u : 2u) + ((x_face ? n_along_x : -b.sin_yaw * n.x() + b.cos_yaw * n.y()) > 0 ? 1u : 0u);
  const bool flat = b.kind == scene::PrimitiveKind::kBox || b.kind == scene::PrimitiveKind::kCylinder;
  const double window_top = flat ? b.eave_z - 0.9 : b.eave_z - 0.3;  // parapet, or the eaves

  const Vector2d uv(along, h);
  Vector3f c = look.wall_color * (0.92f + 0.16f * Octave(uv, 1.2, 31 + building, footprint_m));
  // Storeys of 3.5 m, bays of ~3 m fitted to the wall; no windows in the 0.9 m parapet.
  constexpr double kStorey = 3.5;
  const double bay = length / std::max(1.0, std::round(length / 3.0));
  const double row = std::floor(h / kStorey), col = std::floor(along / bay);
  const double fv = h / kStorey - row, fu = along / bay - col;
  if (fv < 0.04 && h > 1.0) return 0.82f * c;  // slab line at each floor
  if (h > 0.3 && p.z() < window_top && fv > 0.28 && fv < 0.78 && fu > 0.18 && fu < 0.82) {
    const uint32_t seed = 1000u + 4u * static_cast<uint32_t>(building) + face;
    const float r = Hash01(static_cast<int64_t>(col), static_cast<int64_t>(row), seed);
    Vector3f glass = Mix(Vector3f(0.10f, 0.14f, 0.22f), Vector3f(0.36f, 0.46f, 0.60f), r);
    if (r > 0.93f) glass = Vector3f(0.85f, 0.78f, 0.50f);  // a lit room
    const float frame = static_cast<float>(std::min(fu - 0.18, 0.82 - fu) < 0.03 ? 0.6 : 1.0);
    return frame * glass;
  }
  return c;
}

Vector3f Roof(const BuildingLook& look, int32_t building, const Vector3d& p, double footprint_m) {
  const PartLook& b = look.PartAt(p);
  const Vector2d q = b.ToPart(p);
  if (b.kind == scene::PrimitiveKind::kBox) {
    const double to_edge = std::min(b.half_size.x() - std::abs(q.x()), b.half_size.y() - std::abs(q.y()));
    if (to_edge < 0.4) return Vector3f(0.66f, 0.64f, 0.60f);  // parapet
  } else if (b.kind == scene::PrimitiveKind::kCylinder) {
    if (-b.Outside(p) < 0.4) return Vector3f(0.66f, 0.64f, 0.60f);
  } else if (b.kind != scene::PrimitiveKind::kDome) {
    // Pitched roofs: rows of tiles every 0.35 m up the slope (faded out where they would alias).
    const float rows = 0.5f + 0.5f * static_cast<float>(std::sin(2 * M_PI * p.z() / 0.35 * 2.5));
    const float r = Resolved(footprint_m, 0.35);
    return look.roof_color * (0.85f + 0.1f * Octave(q, 1.5, 51 + building, footprint_m) + 0.12f * r * (rows - 0.5f));
  }
  return look.roof_color * (0.85f + 0.3f * Octave(q, 1.5, 51 + building, footprint_m));
}

Vector3f Vegetation(const Vector3f& base, const Vector3d& p, double footprint_m) {
  const Vector2d q(p.x() + 0.7 * p.z(), p.y() - 0.5 * p.z());
  const float leaves = 0.6f * Octave(q, 0.6, 61, footprint_m) + 0.4f * Octave(q, 0.25, 62, footprint_m);
  return base * (0.7f + 0.6f * leaves);
}

Vector3f Sky(const Vector3d& direction_in_world) {
  const double elevation = direction_in_world.z() / direction_in_world.norm();
  const Vector3f horizon(0.82f, 0.87f, 0.92f), zenith(0.36f, 0.56f, 0.84f);
  // Below the horizon, past the terrain's edge: hazy distant fields.
  if (elevation <= 0) return Mix(horizon, Vector3f(0.50f, 0.57f, 0.46f), SmoothStep(0.0f, 0.12f, static_cast<float>(-elevation)));
  return Mix(horizon, zenith, static_cast<float>(std::sqrt(elevation)));
}

// ---- Rasteriser ------------------------------------------------------------------------------

struct ScreenVertex {
  double u, v;      // pixels
  double inv_z;     // 1 / depth along the optical axis
};

// Edge function of the directed edge p -> q: (q - p) x (x - p). It is always evaluated from the
// lexicographically smaller end, so the two triangles sharing an edge compute bit-identical values
// of opposite sign and no pixel centre on a shared edge is missed (a watertight mesh stays so).
struct Edge {
  double pu, pv, du, dv, sign;
  static Edge Make(const ScreenVertex& p, const ScreenVertex& q) {
    if (p.u < q.u || (p.u == q.u && p.v < q.v)) return {p.u, p.v, q.u - p.u, q.v - p.v, 1.0};
    return {q.u, q.v, p.u - q.u, p.v - q.v, -1.0};
  }
  double operator()(double x, double y) const { return sign * (du * (y - pv) - dv * (x - pu)); }
};

class Rasterizer {
 public:
  Rasterizer(const PinholeIntrinsics& k, double near_m, float* depth, uint32_t* triangle)
      : k_(k), near_(near_m), depth_(depth), triangle_(triangle) {
    // Frustum side planes through the camera centre at the image borders (u = -0.5, w - 0.5, ...).
    left_ = (-0.5 - k.cx) / k.fx;
    right_ = (k.width - 0.5 - k.cx) / k.fx;
    top_ = (-0.5 - k.cy) / k.fy;
    bottom_ = (k.height - 0.5 - k.cy) / k.fy;
  }

  // Triangle with vertices in the camera frame.
  void Draw(const Vector3d& a, const Vector3d& b, const Vector3d& c, uint32_t id) {
    const std::array<const Vector3d*, 3> v = {&a, &b, &c};
    auto all_outside = [&](auto outside) { return outside(*v[0]) && outside(*v[1]) && outside(*v[2]); };
    if (all_outside([&](const Vector3d& p) { return p.z() < near_; }) ||
        all_outside([&](const Vector3d& p) { return p.x() < left_ * p.z(); }) ||
        all_outside([&](const Vector3d& p) { return p.x() > right_ * p.z(); }) ||
        all_outside([&](const Vector3d& p) { return p.y() < top_ * p.z(); }) ||
        all_outside([&](const Vector3d& p) { return p.y() > bottom_ * p.z(); })) {
      return;
    }
    // Sutherland-Hodgman against z = near: a triangle becomes a triangle or a quad. The crossing
    // point is always computed from the inside end, so neighbours clip a shared edge identically.
    std::array<Vector3d, 4> poly;
    int n = 0;
    for (int i = 0; i < 3; ++i) {
      const Vector3d& cur = *v[i];
      const Vector3d& next = *v[(i + 1) % 3];
      const bool cur_in = cur.z() >= near_, next_in = next.z() >= near_;
      if (cur_in) poly[n++] = cur;
      if (cur_in != next_in) {
        const Vector3d& in = cur_in ? cur : next;
        const Vector3d& out = cur_in ? next : cur;
        Vector3d p = in + (near_ - in.z()) / (out.z() - in.z()) * (out - in);
        p.z() = near_;
        poly[n++] = p;
      }
    }
    std::array<ScreenVertex, 4> s;
    for (int i = 0; i < n; ++i) {
      const double inv_z = 1.0 / poly[i].z();
      s[i] = {k_.fx * poly[i].x() * inv_z + k_.cx, k_.fy * poly[i].y() * inv_z + k_.cy, inv_z};
    }
    for (int i = 1; i + 1 < n; ++i) Fill(s[0], s[i], s[i + 1], id);
  }

 private:
  void Fill(const ScreenVertex& a, const ScreenVertex& b, const ScreenVertex& c, uint32_t id) {
    const double area = (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
    if (!(std::abs(area) > 1e-12)) return;  // degenerate, or NaN
    auto first = [](double lo, int size) { return static_cast<int>(std::ceil(std::clamp(lo, -1.0, double(size)))); };
    auto last = [](double hi, int size) { return static_cast<int>(std::floor(std::clamp(hi, -1.0, double(size)))); };
    const int x0 = std::max(0, first(std::min({a.u, b.u, c.u}), k_.width));
    const int x1 = std::min(k_.width - 1, last(std::max({a.u, b.u, c.u}), k_.width));
    const int y0 = std::max(0, first(std::min({a.v, b.v, c.v}), k_.height));
    const int y1 = std::min(k_.height - 1, last(std::max({a.v, b.v, c.v}), k_.height));
    if (x0 > x1 || y0 > y1) return;
    const double orient = area > 0 ? 1.0 : -1.0;
    const Edge e_a = Edge::Make(b, c), e_b = Edge::Make(c, a), e_c = Edge::Make(a, b);
    for (int y = y0; y <= y1; ++y) {
      float* depth_row = depth_ + static_cast<size_t>(y) * k_.width;
      uint32_t* triangle_row = triangle_ + static_cast<size_t>(y) * k_.width;
      // Each edge function is affine in x along the row: the x where all three are >= 0 lie in
      // [lo, hi]. Only that span (one pixel of margin for rounding) is tested, with the exact
      // test below deciding: the same pixels as testing the whole box (issue 19: most of a
      // slanted triangle's box is outside it).
      double lo = x0, hi = x1;
      for (const Edge* e : {&e_a, &e_b, &e_c}) {
        const double slope = -orient * e->sign * e->dv;  // d(w)/dx
        const double at0 = orient * (*e)(0.0, y);        // w at x = 0
        if (slope > 0) {
          lo = std::max(lo, -at0 / slope);
        } else if (slope < 0) {
          hi = std::min(hi, -at0 / slope);
        }
      }
      int xs = x0, xe = x1;
      if (std::isfinite(lo) && std::isfinite(hi)) {
        if (lo > hi + 2) continue;
        xs = std::max(x0, static_cast<int>(std::floor(std::max(lo, -1e9))) - 1);
        xe = std::min(x1, static_cast<int>(std::ceil(std::min(hi, 1e9))) + 1);
      }
      for (int x = xs; x <= xe; ++x) {
        const double wa = orient * e_a(x, y), wb = orient * e_b(x, y), wc = orient * e_c(x, y);
        if (wa < 0 || wb < 0 || wc < 0) continue;
        const double sum = wa + wb + wc;
        if (!(sum > 0)) continue;
        // 1/z is affine in screen space: the perspective-correct depth at the pixel centre.
        const auto depth = static_cast<float>(sum / (wa * a.inv_z + wb * b.inv_z + wc * c.inv_z));
        if (depth < depth_row[x]) {
          depth_row[x] = depth;
          triangle_row[x] = id;
        }
      }
    }
  }

  const PinholeIntrinsics& k_;
  double near_;
  float* depth_;
  uint32_t* triangle_;
  double left_, right_, top_, bottom_;
};

// Movers as boxes: a person is a body and a head, a car a chassis and a glassy cabin.
void AppendMover(const scene::SyntheticCampus& campus, const scene::Mover& mover, double t_s, TriangleMesh& mesh,
                 std::vector<Surface>& surfaces) {
  const scene::MoverState state = scene::MoverAt(campus, mover, t_s);
  if (!state.position_m.allFinite() || !std::isfinite(state.heading_rad)) return;
  const double width = mover.size_m.x(), length = mover.size_m.y(), height = mover.size_m.z();
  const Vector3d forward(std::cos(state.heading_rad), std::sin(state.heading_rad), 0);
  const size_t first = mesh.TriangleCount();
  auto box = [&](const Vector3d& base, const Vector3d& extent, const Vector3f& color) {
    const size_t before = mesh.TriangleCount();
    scene::AppendBox(mesh, base, state.heading_rad, extent, color, color, -1, SurfaceMaterial::kObject, SurfaceMaterial::kObject);
    for (size_t t = before; t < mesh.TriangleCount(); ++t) {
      Surface s;
      s.material = SurfaceMaterial::kObject;
      s.color = color;
      surfaces.push_back(s);
    }
  };
  if (mover.kind == scene::MoverKind::kPerson) {
    const double body = 0.86 * height;
    box(state.position_m, Vector3d(length, width, body), mover.color);
    box(state.position_m + Vector3d(0, 0, body), Vector3d(0.22, 0.20, height - body), Vector3f(0.86f, 0.68f, 0.55f));
  } else {
    const double chassis = 0.55 * height;
    box(state.position_m, Vector3d(length, width, chassis), mover.color);
    box(state.position_m + Vector3d(0, 0, chassis) - 0.05 * length * forward, Vector3d(0.55 * length, 0.9 * width, height - chassis),
        Mix(mover.color, Vector3f(0.12f, 0.16f, 0.22f), 0.7f));
  }
  const uint32_t id = kMoverIdBase + mover.id;
  for (size_t t = first; t < mesh.TriangleCount(); ++t) {
    const Eigen::Vector3f p0 = mesh.positions[mesh.indices[3 * t]], p1 = mesh.positions[mesh.indices[3 * t + 1]],
                          p2 = mesh.positions[mesh.indices[3 * t + 2]];
    surfaces[t].object_id = id;
    surfaces[t].cls = mover.kind == scene::MoverKind::kPerson ? PixelClass::kPerson : PixelClass::kVehicle;
    surfaces[t].normal = (p1 - p0).cross(p2 - p0).normalized();
  }
}

}  // namespace

std::string RendererOptions::Check() const {
  if (!std::isfinite(terrain_resolution_m) || terrain_resolution_m < 0.05 || terrain_resolution_m > 50) {
    return "terrain_resolution_m must be in [0.05, 50]";
  }
  if (!sun_direction.allFinite() || sun_direction.norm() < 1e-9) return "sun_direction must be finite and non-zero";
  if (!std::isfinite(near_m) || near_m < 1e-4 || near_m > 10) return "near_m must be in [1e-4, 10]";
  return {};
}

namespace {

// One view of a fixed camera: the image as the fixed static triangles alone leave it (depth and
// triangle per pixel, and each pixel's shading once some frame has shaded it).
struct StaticLayer {
  PinholeIntrinsics k;
  Rigid3d pose;
  std::vector<float> depth;
  std::vector<uint32_t> triangle;
  std::vector<uint8_t> shaded;  // 1: bgr, object_id and class_id below hold the pixel's shading
  std::vector<uint8_t> bgr;
  std::vector<uint32_t> object_id;
  std::vector<uint8_t> class_id;
  std::mutex mu;  // one render at a time uses (and fills in) the layer
};

bool SameView(const PinholeIntrinsics& a, const Rigid3d& pa, const PinholeIntrinsics& b, const Rigid3d& pb) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy &&
         pa.translation == pb.translation && pa.rotation.coeffs() == pb.rotation.coeffs();
}

}  // namespace

struct CampusRenderer::Impl {
  scene::SyntheticCampus campus;
  Options options;
  Vector3f sun;                              // unit, towards the sun
  std::vector<Eigen::Vector3f> positions;    // static vertices, local frame
  std::vector<uint32_t> indices;             // three per static triangle
  std::vector<Surface> surfaces;             // one per static triangle
  std::vector<BuildingLook> buildings;       // one per campus building
  std::vector<SwayingCrown> crowns;          // one per tree, into positions
  // Triangles [0, fixed_triangles) and vertices [0, fixed_vertices) are the fixed static scene
  // (no trees); the trees follow.
  size_t fixed_triangles = 0, fixed_vertices = 0;
  // reuse_static_layer: the last view rendered, and the layer of the view rendered twice in a row.
  mutable std::mutex view_mu;
  mutable std::optional<std::pair<PinholeIntrinsics, Rigid3d>> last_view;
  mutable std::shared_ptr<StaticLayer> layer;
};

CampusRenderer::CampusRenderer(const scene::SyntheticCampus& campus, Options options) {
  if (const std::string why = options.Check(); !why.empty()) throw std::invalid_argument("CampusRenderer: " + why);
  auto impl = std::make_unique<Impl>();
  impl->campus = campus;
  impl->options = options;
  impl->sun = options.sun_direction.normalized().cast<float>();

  // The static mesh without trees, then the trees one by one so each crown's vertex range is
  // known (waving vegetation moves them).
  scene::SyntheticCampus bare = campus;
  bare.trees.clear();
  TriangleMesh mesh = scene::BuildStaticMesh(bare, options.terrain_resolution_m);
  impl->fixed_triangles = mesh.TriangleCount();
  impl->fixed_vertices = mesh.positions.size();
  for (size_t i = 0; i < campus.trees.size(); ++i) {
    const scene::Tree& tree = campus.trees[i];
    SwayingCrown crown;
    crown.first_vertex = scene::AppendTree(mesh, campus, tree);
    crown.end_vertex = mesh.positions.size();
    crown.bottom_z = static_cast<float>(campus.TerrainHeight(tree.position_m.x(), tree.position_m.y()) + tree.trunk_height_m);
    crown.height_m = static_cast<float>(2 * tree.crown_radius_m);
    crown.phase_rad = static_cast<float>(2 * M_PI * Hash01(static_cast<int64_t>(i), 0, 77));
    impl->crowns.push_back(crown);
  }
  impl->positions = std::move(mesh.positions);
  impl->indices = std::move(mesh.indices);
  impl->surfaces.resize(impl->indices.size() / 3);
  for (size_t t = 0; t < impl->surfaces.size(); ++t) {
    Surface& s = impl->surfaces[t];
    const Eigen::Vector3f& p0 = impl->positions[impl->indices[3 * t]];
    const Eigen::Vector3f& p1 = impl->positions[impl->indices[3 * t + 1]];
    const Eigen::Vector3f& p2 = impl->positions[impl->indices[3 * t + 2]];
    s.material = mesh.triangle_material[t];
    s.building = mesh.triangle_object[t];
    s.normal = (p1 - p0).cross(p2 - p0).normalized();
    s.color = mesh.colors[impl->indices[3 * t]];
    switch (s.material) {
      case SurfaceMaterial::kTerrain: s.cls = PixelClass::kTerrain; s.object_id = kGroundId; break;
      case SurfaceMaterial::kRoad: s.cls = PixelClass::kRoad; s.object_id = kGroundId; break;
      case SurfaceMaterial::kWall: s.cls = PixelClass::kWall; break;
      case SurfaceMaterial::kRoof: s.cls = PixelClass::kRoof; break;
      case SurfaceMaterial::kVegetation: s.cls = PixelClass::kVegetation; s.object_id = kVegetationId; break;
      case SurfaceMaterial::kObject: s.cls = PixelClass::kStaticObject; s.object_id = kStaticObjectId; break;
    }
    if (s.building >= 0) s.object_id = kBuildingIdBase + static_cast<uint32_t>(s.building);
    if (s.material == SurfaceMaterial::kTerrain || s.material == SurfaceMaterial::kRoad) {
      const Vector2d a = p0.head<2>().cast<double>(), b = p1.head<2>().cast<double>(), c = p2.head<2>().cast<double>();
      const Vector2d centre = (a + b + c) / 3;
      const double radius = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()}) + 0.5;
      s.may_be_road = MayBeRoad(campus, centre, radius);
    }
  }

  const std::array<Vector3f, 5> wall_palette = {Vector3f(0.80f, 0.74f, 0.62f), Vector3f(0.74f, 0.74f, 0.72f),
                                                Vector3f(0.62f, 0.36f, 0.28f), Vector3f(0.86f, 0.80f, 0.60f),
                                                Vector3f(0.58f, 0.60f, 0.62f)};
  const std::array<Vector3f, 4> roof_palette = {Vector3f(0.44f, 0.23f, 0.17f), Vector3f(0.28f, 0.28f, 0.30f),
                                                Vector3f(0.46f, 0.45f, 0.43f), Vector3f(0.36f, 0.20f, 0.16f)};
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    const scene::BoxBuilding& b = campus.buildings[i];
    BuildingLook look;
    look.ground_z = campus.BuildingBase(b) + 0.5;
    for (const scene::BuildingPart& part : b.Parts()) {
      PartLook pl;
      pl.kind = part.kind;
      pl.center = part.center_m;
      pl.cos_yaw = std::cos(part.yaw_rad);
      pl.sin_yaw = std::sin(part.yaw_rad);
      pl.half_size = 0.5 * part.size_m;
      pl.eave_z = campus.BuildingGround(b) + part.height_m;
      look.parts.push_back(pl);
    }
    look.wall_color = wall_palette[Hash(static_cast<int64_t>(i), 0, 7) % wall_palette.size()];
    look.roof_color = roof_palette[Hash(static_cast<int64_t>(i), 1, 7) % roof_palette.size()];
    impl->buildings.push_back(look);
  }
  impl_ = std::move(impl);
}

CampusRenderer::CampusRenderer(CampusRenderer&&) noexcept = default;
CampusRenderer& CampusRenderer::operator=(CampusRenderer&&) noexcept = default;
CampusRenderer::~CampusRenderer() = default;

const CampusRenderer::Options& CampusRenderer::options() const { return impl_->options; }

SimImage CampusRenderer::Render(const PinholeIntrinsics& k, const Rigid3d& world_from_camera, double t_s, Stats* stats,
                                const std::vector<uint8_t>* shade_only) const {
  SimImage image;
  if (!k.Check().empty() || !world_from_camera.translation.allFinite() || !world_from_camera.rotation.coeffs().allFinite()) {
    return image;
  }
  const Impl& m = *impl_;
  const int w = k.width, h = k.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  image.width = w;
  image.height = h;
  image.bgr.resize(3 * pixels);
  image.object_id.assign(pixels, kSkyId);
  image.class_id.assign(pixels, static_cast<uint8_t>(PixelClass::kSky));
  image.depth_m.assign(pixels, std::numeric_limits<float>::infinity());
  std::vector<uint32_t> triangle(pixels, kNoTriangle);

  // A fixed camera's second render of the same view keeps the fixed static scene (StaticLayer).
  std::shared_ptr<StaticLayer> layer;
  bool build_layer = false;
  if (m.options.reuse_static_layer) {
    std::lock_guard lock(m.view_mu);
    if (m.layer && SameView(m.layer->k, m.layer->pose, k, world_from_camera)) {
      layer = m.layer;
    } else if (m.last_view && SameView(m.last_view->first, m.last_view->second, k, world_from_camera)) {
      build_layer = true;
    }
    m.last_view = std::make_pair(k, world_from_camera);
  }
  std::unique_lock<std::mutex> layer_lock;
  if (layer) {
    layer_lock = std::unique_lock(layer->mu);
    image.depth_m = layer->depth;
    triangle = layer->triangle;
  }

  const Eigen::Matrix3d world_from_camera_rot = world_from_camera.rotation.toRotationMatrix();
  const Eigen::Matrix3d camera_from_world_rot = world_from_camera_rot.transpose();
  const Vector3d camera_in_world = world_from_camera.translation;
  const Vector3d camera_from_world_t = -(camera_from_world_rot * camera_in_world);

  // Static triangles first (ids 0..n-1: the fixed scene, then the trees), then this frame's movers
  // (ids n..). With a layer the fixed scene is already in the buffers.
  Rasterizer raster(k, m.options.near_m, image.depth_m.data(), triangle.data());
  std::vector<Vector3d> v_cam(m.positions.size());
  for (size_t i = layer ? m.fixed_vertices : 0; i < m.positions.size(); ++i) {
    v_cam[i] = camera_from_world_rot * m.positions[i].cast<double>() + camera_from_world_t;
  }
  if (m.options.waving_vegetation && !m.crowns.empty()) {
    const auto sway_start = std::chrono::steady_clock::now();
    std::vector<Eigen::Vector3f> swayed = m.positions;
    SwayVegetation(*m.options.waving_vegetation, t_s, m.positions, m.crowns, swayed);
    for (const SwayingCrown& crown : m.crowns) {
      for (size_t i = crown.first_vertex; i < crown.end_vertex; ++i) {
        v_cam[i] = camera_from_world_rot * swayed[i].cast<double>() + camera_from_world_t;
      }
    }
    if (stats) stats->waving_vegetation_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - sway_start).count();
  }
  const size_t n_static = m.surfaces.size();
  auto draw_static = [&](size_t begin, size_t end) {
    for (size_t t = begin; t < end; ++t) {
      raster.Draw(v_cam[m.indices[3 * t]], v_cam[m.indices[3 * t + 1]], v_cam[m.indices[3 * t + 2]], static_cast<uint32_t>(t));
    }
  };
  if (!layer) draw_static(0, m.fixed_triangles);
  if (build_layer) {
    auto fresh = std::make_shared<StaticLayer>();
    fresh->k = k;
    fresh->pose = world_from_camera;
    fresh->depth = image.depth_m;
    fresh->triangle = triangle;
    fresh->shaded.assign(pixels, 0);
    fresh->bgr.resize(3 * pixels);
    fresh->object_id.resize(pixels);
    fresh->class_id.resize(pixels);
    layer = std::move(fresh);
    layer_lock = std::unique_lock(layer->mu);
  }
  draw_static(m.fixed_triangles, n_static);
  TriangleMesh movers;
  std::vector<Surface> mover_surfaces;
  if (m.options.draw_movers) {
    for (const scene::Mover& mover : m.campus.movers) AppendMover(m.campus, mover, t_s, movers, mover_surfaces);
    auto cam = [&](uint32_t i) { return Vector3d(camera_from_world_rot * movers.positions[i].cast<double>() + camera_from_world_t); };
    for (size_t t = 0; t < movers.TriangleCount(); ++t) {
      raster.Draw(cam(movers.indices[3 * t]), cam(movers.indices[3 * t + 1]), cam(movers.indices[3 * t + 2]),
                  static_cast<uint32_t>(n_static + t));
    }
  }

  // Shading: the surface point is the pixel's ray scaled by the interpolated depth, i.e. the
  // perspective-correct local-frame position; textures are functions of that position. A pixel
  // that still shows the layer's fixed scene (or sky) takes the layer's shading once known.
  const Vector3f sun = m.sun;
  if (shade_only && shade_only->size() != pixels) shade_only = nullptr;
  for (int y = 0; y < h; ++y) {
    const double yn = (y - k.cy) / k.fy;
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (shade_only && !(*shade_only)[i]) continue;
      const uint32_t tri = triangle[i];
      const bool fixed_pixel = layer && layer->triangle[i] == tri;
      if (fixed_pixel && layer->shaded[i]) {
        for (int c = 0; c < 3; ++c) image.bgr[3 * i + c] = layer->bgr[3 * i + c];
        image.object_id[i] = layer->object_id[i];
        image.class_id[i] = layer->class_id[i];
        continue;
      }
      const double xn = (x - k.cx) / k.fx;
      const Vector3d ray_in_world = world_from_camera_rot * Vector3d(xn, yn, 1.0);  // z_cam = 1
      Vector3f rgb(0, 0, 0);
      if (tri == kNoTriangle) {
        rgb = Sky(ray_in_world);
      } else {
        const Surface& s = tri < n_static ? m.surfaces[tri] : mover_surfaces[tri - n_static];
        const double depth = image.depth_m[i];
        const Vector3d p = camera_in_world + depth * ray_in_world;
        const double distance = depth * ray_in_world.norm();
        // Ground size of one pixel, stretched at grazing view: drives texture anti-aliasing.
        const double cos_view = std::abs(s.normal.cast<double>().dot(ray_in_world)) / ray_in_world.norm();
        const double footprint_m = distance / k.fx / std::max(cos_view, 0.1);
        switch (s.material) {
          case SurfaceMaterial::kTerrain:
          case SurfaceMaterial::kRoad: rgb = Ground(m.campus, p.head<2>(), footprint_m, s.may_be_road); break;
          case SurfaceMaterial::kWall: rgb = Wall(m.buildings[s.building], s.building, p, s.normal, footprint_m); break;
          case SurfaceMaterial::kRoof: rgb = Roof(m.buildings[s.building], s.building, p, footprint_m); break;
          case SurfaceMaterial::kObject: rgb = s.color; break;
          case SurfaceMaterial::kVegetation: rgb = Vegetation(s.color, p, footprint_m); break;
        }
        rgb *= 0.45f + 0.55f * std::max(0.0f, s.normal.dot(sun));
        const float haze = 1.0f - std::exp(static_cast<float>(-distance / 900.0));
        rgb = Mix(rgb, Vector3f(0.74f, 0.77f, 0.78f), haze);
        image.object_id[i] = s.object_id;
        image.class_id[i] = static_cast<uint8_t>(s.cls);
      }
      for (int c = 0; c < 3; ++c) {
        image.bgr[3 * i + c] = static_cast<uint8_t>(255.0f * std::clamp(rgb[2 - c], 0.0f, 1.0f) + 0.5f);
      }
      if (fixed_pixel) {
        for (int c = 0; c < 3; ++c) layer->bgr[3 * i + c] = image.bgr[3 * i + c];
        layer->object_id[i] = image.object_id[i];
        layer->class_id[i] = image.class_id[i];
        layer->shaded[i] = 1;
      }
    }
  }
  if (build_layer) {
    std::lock_guard lock(m.view_mu);
    m.layer = layer;
  }
  return image;
}

}  // namespace ave::sim
