#include "sensor_agent/sim/studio.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/geometry/bvh.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/lidar_common.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::sim {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Eigen::Vector3f;

constexpr double kPi = 3.14159265358979323846;
constexpr double kWalkRadius_m = 0.6;     // the actor walks a circle of this radius around the origin
constexpr double kWalkSpeed_mps = 0.7;
constexpr double kStrideHz = 0.9;         // full walk cycles per second
constexpr double kFloorRadius_m = 7;      // the floor disc; beyond it the studio wall
constexpr double kShadowFactor = 0.45;    // floor brightness in the key light's shadow
constexpr double kHorizontalFovDeg = 60;
constexpr double kRingHeight_m = 1.8;
constexpr double kOverheadHeight_m = 6.0;

// Part colours (BGR order is applied when writing pixels).
const Vector3f kShirt(0.20f, 0.45f, 0.80f), kTrousers(0.25f, 0.22f, 0.30f), kSkin(0.88f, 0.70f, 0.58f), kShoes(0.12f, 0.10f, 0.10f);

Matrix3d RotZ(double a) { return Eigen::AngleAxisd(a, Vector3d::UnitZ()).toRotationMatrix(); }
Matrix3d RotY(double a) { return Eigen::AngleAxisd(a, Vector3d::UnitY()).toRotationMatrix(); }

// A segment hangs from a joint: it spans [-hx, hx] x [-hy, hy] x [-length, 0] in the joint frame
// (world_from_joint = R, joint), i.e. a limb segment pointing down its frame's -z.
struct Segment {
  Matrix3d R;
  Vector3d joint;
  double hx, hy, length;
};

// One triangle of a part, with its colour. Every part is closed, wound outward (counter-clockwise
// seen from outside) and shares no vertex with another part.
void AddTriangle(TriangleMesh& mesh, std::vector<Vector3f>& colors, uint32_t a, uint32_t b, uint32_t c, const Vector3f& color) {
  mesh.indices.insert(mesh.indices.end(), {a, b, c});
  mesh.triangle_material.push_back(SurfaceMaterial::kObject);
  mesh.triangle_object.push_back(-1);
  colors.push_back(color);
}

// The segment's box (StudioActor::kBoxes).
void AppendBox(TriangleMesh& mesh, std::vector<Vector3f>& colors, const Segment& g, const Vector3f& color) {
  const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
  for (int k = 0; k < 8; ++k) {
    const Vector3d local(k & 1 ? g.hx : -g.hx, k & 2 ? g.hy : -g.hy, k & 4 ? 0.0 : -g.length);
    mesh.positions.push_back((g.joint + g.R * local).cast<float>());
  }
  const uint32_t q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : q) {
    AddTriangle(mesh, colors, first + f[0], first + f[1], first + f[2], color);
    AddTriangle(mesh, colors, first + f[0], first + f[2], first + f[3], color);
  }
}

// How a segment becomes a body part (StudioActor::kBody): along the segment's axis a stack of
// rings, each the same elliptic kBodySides-gon (semi-axes hx, hy scaled so that the polygon's
// area is the box's cross-section, 4 hx hy; the head's is inscribed in its box instead) scaled by
// a width profile r(z) = 1 + taper (z - z_mid) / L - round_depth (2 - g_top(z) - g_bottom(z)),
// g a quarter-ellipse rising from 0 at the end to 1 at `*_round` metres from it (1 throughout
// for a flat end). r is concave in z (a sum of concave terms), so every part is convex; a
// rounded end is a flat disc of width 1 -+ taper / 2 - round_depth. The part may reach past the joint
// (top_ext) and the segment's end (bottom_ext) so that neighbours overlap at knees, elbows,
// hips and shoulders as a body does, instead of meeting at a pinched waist.
struct PartShape {
  double top_ext = 0, bottom_ext = 0;      // m beyond the segment's ends
  double top_round = 0, bottom_round = 0;  // axial length of each rounded end, m; 0: a flat end
  double round_depth = 0.8;                // how much narrower the end discs are, in [0, 1)
  double taper = 0;                        // top width minus bottom width (the mean width is 1)
  bool keep_area = true;                   // false: the ellipse inscribed in the box (the head)
};
constexpr int kBodySides = 20;
constexpr int kCapRings = 4;  // rings on each rounded end after its disc

void AppendBodyPart(TriangleMesh& mesh, std::vector<Vector3f>& colors, const Segment& g, const PartShape& p, const Vector3f& color) {
  const double z_top = p.top_ext, z_bottom = -g.length - p.bottom_ext, span = z_top - z_bottom;
  // Ring heights, bottom to top: each rounded end's rings at cos-spaced depths, then the other's.
  std::vector<double> z;
  for (int j = 0; j <= (p.bottom_round > 0 ? kCapRings : 0); ++j) z.push_back(z_bottom + p.bottom_round * (1 - std::cos(j * kPi / (2 * kCapRings))));
  for (int j = p.top_round > 0 ? kCapRings : 0; j >= 0; --j) {
    const double zj = z_top - p.top_round * (1 - std::cos(j * kPi / (2 * kCapRings)));
    if (zj > z.back() + 1e-9) z.push_back(zj);  // the head's two ends meet at its middle ring
  }
  auto rise = [](double d, double k) { return k <= 0 || d >= k ? 1.0 : std::sqrt(std::max(0.0, 1 - (1 - d / k) * (1 - d / k))); };
  const double n = kBodySides;
  const double polygon_area_per_ab = n / 2 * std::sin(2 * kPi / n);  // of a unit-semi-axes N-gon
  const double scale = p.keep_area ? std::sqrt(4 / polygon_area_per_ab) : 1.0;
  const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
  for (const double zj : z) {
    const double r = 1 + p.taper * ((zj - z_bottom) / span - 0.5) -
                     p.round_depth * (2 - rise(z_top - zj, p.top_round) - rise(zj - z_bottom, p.bottom_round));
    for (int i = 0; i < kBodySides; ++i) {
      const double phi = 2 * kPi * (i + 0.5) / n;
      const Vector3d local(scale * g.hx * r * std::cos(phi), scale * g.hy * r * std::sin(phi), zj);
      mesh.positions.push_back((g.joint + g.R * local).cast<float>());
    }
  }
  const uint32_t rings = static_cast<uint32_t>(z.size()), sides = kBodySides;
  auto v = [&](uint32_t ring, uint32_t i) { return first + ring * sides + i % sides; };
  for (uint32_t j = 0; j + 1 < rings; ++j) {
    for (uint32_t i = 0; i < sides; ++i) {  // i runs counter-clockwise seen from +z
      AddTriangle(mesh, colors, v(j, i), v(j, i + 1), v(j + 1, i + 1), color);
      AddTriangle(mesh, colors, v(j, i), v(j + 1, i + 1), v(j + 1, i), color);
    }
  }
  for (uint32_t i = 1; i + 1 < sides; ++i) {
    AddTriangle(mesh, colors, v(rings - 1, 0), v(rings - 1, i), v(rings - 1, i + 1), color);  // top disc, facing +z
    AddTriangle(mesh, colors, v(0, 0), v(0, i + 1), v(0, i), color);                          // bottom disc, facing -z
  }
}

TriangleMesh ActorMesh(double t_s, StudioActor actor, std::vector<Vector3f>* triangle_colors) {
  std::vector<Vector3f> local_colors;
  std::vector<Vector3f>& colors = triangle_colors ? *triangle_colors : local_colors;
  colors.clear();
  const StudioActorState s = StudioActorAt(t_s);
  TriangleMesh mesh;
  auto part = [&](const Matrix3d& R, const Vector3d& joint, double hx, double hy, double length, const Vector3f& color, const PartShape& shape) {
    const Segment g{R, joint, hx, hy, length};
    if (actor == StudioActor::kBoxes) AppendBox(mesh, colors, g, color);
    else AppendBodyPart(mesh, colors, g, shape, color);
  };
  // Body part shapes: {top_ext, bottom_ext, top_round, bottom_round, round_depth, taper, keep_area}.
  const PartShape thigh_shape{0.03, 0.03, 0.06, 0.05, 0.8, 0.25, true}, shin_shape{0.02, 0.02, 0.05, 0.04, 0.8, 0.25, true};
  const PartShape shoe_shape{0, 0, 0.035, 0, 0.6, 0, true};  // flat sole
  const PartShape upper_arm_shape{0.03, 0.02, 0.05, 0.04, 0.8, 0.15, true}, forearm_shape{0.02, 0, 0.035, 0.05, 0.8, 0.2, true};
  const PartShape torso_shape{0, 0, 0.09, 0.06, 0.7, 0.12, true}, neck_shape{0.02, 0.02, 0.015, 0.015, 0.3, 0, true};
  const PartShape head_shape{0, 0, 0.12, 0.12, 0.85, 0, false};  // an ellipsoid-like solid filling its box
  const Matrix3d body = RotZ(s.heading_rad);  // body frame: x forward, y left, z up
  const double swing = std::sin(s.phase_rad);
  const double pelvis_z = 0.92 + 0.02 * std::cos(2 * s.phase_rad);
  const Vector3d pelvis = s.ground_m + Vector3d(0, 0, pelvis_z);
  for (int side : {-1, 1}) {
    // Legs: the left leg (side +1) swings forward when sin(phase) > 0; knees bend on the way forward.
    const double hip = -0.45 * side * swing;  // about the body's y axis: negative swings the foot forward
    const double knee = 0.7 * std::max(0.0, std::sin(s.phase_rad + (side > 0 ? 0.6 : kPi + 0.6)));
    const Matrix3d thigh = body * RotY(hip);
    const Vector3d hip_joint = pelvis + body * Vector3d(0, 0.1 * side, 0);
    part(thigh, hip_joint, 0.075, 0.07, 0.44, kTrousers, thigh_shape);
    const Matrix3d shin = thigh * RotY(knee);
    const Vector3d knee_joint = hip_joint + thigh * Vector3d(0, 0, -0.44);
    part(shin, knee_joint, 0.06, 0.06, 0.42, kTrousers, shin_shape);
    const Vector3d ankle = knee_joint + shin * Vector3d(0, 0, -0.42);
    part(body, ankle + body * Vector3d(0.06, 0, 0.05), 0.12, 0.055, 0.07, kShoes, shoe_shape);
    // Arms swing against the legs; elbows bend a little.
    const double shoulder = 0.35 * side * swing;
    const Matrix3d upper = body * RotY(shoulder);
    const Vector3d shoulder_joint = pelvis + body * Vector3d(0, 0.23 * side, 0.5);
    part(upper, shoulder_joint, 0.05, 0.045, 0.29, kShirt, upper_arm_shape);
    const Matrix3d fore = upper * RotY(-0.25 - 0.2 * std::max(0.0, side * swing));
    part(fore, shoulder_joint + upper * Vector3d(0, 0, -0.29), 0.04, 0.04, 0.27, kSkin, forearm_shape);
  }
  part(body, pelvis + Vector3d(0, 0, 0.56), 0.11, 0.18, 0.58, kShirt, torso_shape);  // torso
  part(body, pelvis + Vector3d(0, 0, 0.63), 0.04, 0.04, 0.08, kSkin, neck_shape);    // neck
  part(body, pelvis + Vector3d(0, 0, 0.87), 0.1, 0.085, 0.24, kSkin, head_shape);    // head
  mesh.normals.assign(mesh.positions.size(), Vector3f::UnitZ());
  mesh.colors.assign(mesh.positions.size(), kShirt);
  return mesh;
}

uint8_t ToByte(double v) { return static_cast<uint8_t>(std::clamp(std::lround(v * 255.0), 0L, 255L)); }

// Floor appearance: light grey vinyl with a faint 0.5 m tile grid.
Vector3d FloorColor(double x, double y) {
  const double fx = x / 0.5 - std::floor(x / 0.5), fy = y / 0.5 - std::floor(y / 0.5);
  const bool seam = fx < 0.02 || fx > 0.98 || fy < 0.02 || fy > 0.98;
  return seam ? Vector3d(0.62, 0.62, 0.60) : Vector3d(0.80, 0.79, 0.76);
}
const Vector3d kWallColor(0.30, 0.34, 0.40);

std::string JsonNumber(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

}  // namespace

std::string StudioSpec::Check() const {
  if (cameras < 1 || cameras > 64) return "cameras must be in [1, 64]";
  if (!std::isfinite(radius_m) || radius_m <= 1 || radius_m > 50) return "radius_m must be in (1, 50]";
  if (!std::isfinite(fps) || fps <= 0 || fps > 120) return "fps must be in (0, 120]";
  if (!std::isfinite(duration_s) || duration_s < 0 || duration_s > 600) return "duration_s must be in [0, 600]";
  if (width < 16 || height < 16 || width > 8192 || height > 8192) return "width and height must be in [16, 8192]";
  return {};
}

StudioActorState StudioActorAt(double t_s) {
  StudioActorState s;
  const double angle = kWalkSpeed_mps / kWalkRadius_m * t_s;  // counter-clockwise around the origin
  s.ground_m = Vector3d(kWalkRadius_m * std::cos(angle), kWalkRadius_m * std::sin(angle), 0);
  s.heading_rad = angle + kPi / 2;
  s.phase_rad = std::fmod(2 * kPi * kStrideHz * t_s, 2 * kPi);
  if (s.phase_rad < 0) s.phase_rad += 2 * kPi;
  return s;
}

Vector3d StudioLightDirection() { return Vector3d(0.55, -0.35, 1.0).normalized(); }

TriangleMesh StudioActorMesh(double t_s, StudioActor actor) { return ActorMesh(t_s, actor, nullptr); }

const char* StudioActorName(StudioActor actor) { return actor == StudioActor::kBoxes ? "boxes" : "body"; }

std::optional<StudioActor> ParseStudioActor(std::string_view name) {
  if (name == "body") return StudioActor::kBody;
  if (name == "boxes") return StudioActor::kBoxes;
  return std::nullopt;
}

std::vector<StudioCamera> StudioCameras(const StudioSpec& spec) {
  std::vector<StudioCamera> cams;
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(spec.width, spec.height, kHorizontalFovDeg);
  const Vector3d target(0, 0, 0.9);
  for (int i = 0; i < spec.cameras; ++i) {
    const double a = 2 * kPi * i / spec.cameras;
    char id[16];
    std::snprintf(id, sizeof(id), "ring%02d", i);
    // Alternate heights a little so the views are not all coplanar (helps a visual hull).
    const double h = kRingHeight_m + (i % 2 ? 0.4 : 0.0);
    cams.push_back({id, k, LookAt(Vector3d(spec.radius_m * std::cos(a), spec.radius_m * std::sin(a), h), target)});
  }
  if (spec.overhead) {
    PinholeIntrinsics top = PinholeIntrinsics::FromFov(spec.width, spec.height, kHorizontalFovDeg);
    cams.push_back({"overhead", top, LookAt(Vector3d(0, 0, kOverheadHeight_m), Vector3d(0, 0, 0))});
  }
  return cams;
}

namespace {

StudioView RenderView(const StudioCamera& camera, const EffectSet& effects, uint64_t seed, int64_t frame_index, double t_s,
                      bool with_actor, StudioActor actor_kind) {
  StudioView view;
  const PinholeIntrinsics& k = camera.intrinsics;
  if (!k.Check().empty() || !std::isfinite(t_s)) return view;
  const int w = k.width, h = k.height;
  view.width = w;
  view.height = h;
  view.bgr.assign(static_cast<size_t>(w) * h * 3, 0);
  view.silhouette.assign(static_cast<size_t>(w) * h, 0);
  view.shadow.assign(static_cast<size_t>(w) * h, 0);

  std::vector<Vector3f> colors;
  const TriangleMesh actor = ActorMesh(t_s, actor_kind, &colors);
  const MeshBvh actor_bvh(actor);
  const Rigid3d camera_from_world = camera.world_from_camera.Inverse();
  const Vector3d eye = camera.world_from_camera.translation;
  const Vector3d light = StudioLightDirection();

  // Actor: z-buffered rasterisation; a pixel is covered when its centre is inside a triangle.
  std::vector<float> depth(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
  std::vector<int32_t> tri_at(static_cast<size_t>(w) * h, -1);
  // The empty studio (with_actor false) rasterises no triangle and casts no shadow.
  for (size_t t = 0; with_actor && t < actor.TriangleCount(); ++t) {
    Vector3d pc[3];
    Eigen::Vector2d uv[3];
    bool ok = true;
    for (int i = 0; i < 3; ++i) {
      pc[i] = camera_from_world * actor.positions[actor.indices[3 * t + i]].cast<double>();
      if (pc[i].z() < 0.05) ok = false;
      uv[i] = Eigen::Vector2d(k.fx * pc[i].x() / pc[i].z() + k.cx, k.fy * pc[i].y() / pc[i].z() + k.cy);
    }
    if (!ok) continue;  // the actor never reaches this close to a camera
    const double area = (uv[1] - uv[0]).x() * (uv[2] - uv[0]).y() - (uv[1] - uv[0]).y() * (uv[2] - uv[0]).x();
    if (std::abs(area) < 1e-12) continue;
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({uv[0].x(), uv[1].x(), uv[2].x()}))));
    const int u1 = std::min(w - 1, static_cast<int>(std::floor(std::max({uv[0].x(), uv[1].x(), uv[2].x()}))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::min({uv[0].y(), uv[1].y(), uv[2].y()}))));
    const int v1 = std::min(h - 1, static_cast<int>(std::floor(std::max({uv[0].y(), uv[1].y(), uv[2].y()}))));
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        double b[3];
        for (int i = 0; i < 3; ++i) {
          const Eigen::Vector2d& a = uv[(i + 1) % 3];
          const Eigen::Vector2d& c = uv[(i + 2) % 3];
          b[i] = ((c.x() - a.x()) * (v - a.y()) - (c.y() - a.y()) * (u - a.x())) / area;
        }
        if (b[0] < 0 || b[1] < 0 || b[2] < 0) continue;
        // Perspective-correct depth: 1/z is affine in the image.
        const double inv_z = b[0] / pc[0].z() + b[1] / pc[1].z() + b[2] / pc[2].z();
        const float z = static_cast<float>(1.0 / inv_z);
        const size_t idx = static_cast<size_t>(v) * w + u;
        if (z < depth[idx]) {
          depth[idx] = z;
          tri_at[idx] = static_cast<int32_t>(t);
        }
      }
    }
  }

  // Shadow candidates: the floor region the actor's bounding box casts onto along the light.
  Eigen::Vector2d shadow_lo(1e9, 1e9), shadow_hi(-1e9, -1e9);
  for (const Vector3f& p : actor.positions) {
    const Vector3d q = p.cast<double>();
    const Eigen::Vector2d on_floor = q.head<2>() - q.z() / light.z() * light.head<2>();
    for (const Eigen::Vector2d& c : {q.head<2>().eval(), on_floor}) {
      shadow_lo = shadow_lo.cwiseMin(c);
      shadow_hi = shadow_hi.cwiseMax(c);
    }
  }

  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t idx = static_cast<size_t>(v) * w + u;
      Vector3d rgb;
      if (tri_at[idx] >= 0) {
        const int32_t t = tri_at[idx];
        const Vector3d p0 = actor.positions[actor.indices[3 * t]].cast<double>(), p1 = actor.positions[actor.indices[3 * t + 1]].cast<double>(),
                       p2 = actor.positions[actor.indices[3 * t + 2]].cast<double>();
        const Vector3d n = (p1 - p0).cross(p2 - p0).normalized();
        rgb = colors[t].cast<double>() * (0.35 + 0.65 * std::max(0.0, n.dot(light)));
        view.silhouette[idx] = 255;
      } else {
        const Vector3d d = camera.world_from_camera.rotation * PixelRay(k, Eigen::Vector2d(u, v));
        const double s = d.z() < -1e-9 ? -eye.z() / d.z() : -1;
        const Vector3d p = eye + s * d;
        if (s > 0 && p.head<2>().norm() < kFloorRadius_m) {
          rgb = FloorColor(p.x(), p.y());
          if (with_actor && (p.head<2>().array() >= shadow_lo.array()).all() && (p.head<2>().array() <= shadow_hi.array()).all() &&
              actor_bvh.Raycast(p, light, 1e-6, 10).has_value()) {
            rgb *= kShadowFactor;
            view.shadow[idx] = 255;
          }
        } else {
          rgb = kWallColor;
        }
      }
      view.bgr[3 * idx + 0] = ToByte(rgb.z());
      view.bgr[3 * idx + 1] = ToByte(rgb.y());
      view.bgr[3 * idx + 2] = ToByte(rgb.x());
    }
  }

  // Camera effects, by the camera pipeline's own functions, in its order.
  const EffectParams* illumination = effects.Find(EffectKind::kIllumination);
  const EffectParams* noise = effects.Find(EffectKind::kCameraNoise);
  if (illumination || noise) {
    SimImage image;
    image.width = w;
    image.height = h;
    image.bgr = std::move(view.bgr);
    // Each camera has its own noise: mix the camera's id into the seed.
    const uint64_t camera_seed = internal::MixSeed(seed, std::hash<std::string>{}(camera.id), 0);
    if (illumination) ApplyIllumination(*illumination, seed, t_s, image);
    if (noise) ApplyCameraNoise(*noise, FrameSeed(camera_seed, frame_index), image);
    view.bgr = std::move(image.bgr);
  }
  return view;
}

}  // namespace

StudioView RenderStudioView(const StudioCamera& camera, const EffectSet& effects, uint64_t seed, int64_t frame_index, double t_s,
                            StudioActor actor) {
  return RenderView(camera, effects, seed, frame_index, t_s, /*with_actor=*/true, actor);
}

StudioView RenderStudioBackground(const StudioCamera& camera, const EffectSet& effects, uint64_t seed) {
  // Frame index -1: its own noise draw, not a copy of any frame's.
  return RenderView(camera, effects, seed, -1, 0.0, /*with_actor=*/false, StudioActor::kBody);
}

absl::Status SimulateStudio(const StudioSpec& spec, const EffectSet& effects, uint64_t seed, const std::string& out_dir) {
  if (const std::string why = spec.Check(); !why.empty()) return absl::InvalidArgumentError("studio: " + why);
  if (const std::string why = internal::MakeDirs(out_dir); !why.empty()) return absl::InternalError(why);
  const std::vector<StudioCamera> cams = StudioCameras(spec);
  const int frames = std::max(1, static_cast<int>(std::floor(spec.duration_s * spec.fps + 1e-9)));

  std::string json = "{\n  \"format\": \"ave-studio-calibration-1\",\n  \"fps\": " + JsonNumber(spec.fps) +
                     ",\n  \"frames\": " + std::to_string(frames) + ",\n  \"floor_z_m\": 0,\n  \"light_direction\": [";
  const Vector3d light = StudioLightDirection();
  json += JsonNumber(light.x()) + ", " + JsonNumber(light.y()) + ", " + JsonNumber(light.z()) + "],\n  \"cameras\": [\n";
  for (size_t c = 0; c < cams.size(); ++c) {
    const StudioCamera& cam = cams[c];
    const PinholeIntrinsics& k = cam.intrinsics;
    const Eigen::Quaterniond& q = cam.world_from_camera.rotation;
    const Vector3d& t = cam.world_from_camera.translation;
    json += "    {\"id\": \"" + cam.id + "\", \"width\": " + std::to_string(k.width) + ", \"height\": " + std::to_string(k.height) +
            ", \"fx\": " + JsonNumber(k.fx) + ", \"fy\": " + JsonNumber(k.fy) + ", \"cx\": " + JsonNumber(k.cx) +
            ", \"cy\": " + JsonNumber(k.cy) + ", \"distortion\": [0, 0, 0, 0, 0],\n     \"world_from_camera\": {\"qw\": " +
            JsonNumber(q.w()) + ", \"qx\": " + JsonNumber(q.x()) + ", \"qy\": " + JsonNumber(q.y()) + ", \"qz\": " + JsonNumber(q.z()) +
            ", \"tx\": " + JsonNumber(t.x()) + ", \"ty\": " + JsonNumber(t.y()) + ", \"tz\": " + JsonNumber(t.z()) + "}}" +
            (c + 1 < cams.size() ? ",\n" : "\n");
  }
  json += "  ]\n}\n";
  {
    std::ofstream out(out_dir + "/calibration.json");
    out << json;
    if (!out) return absl::InternalError("cannot write " + out_dir + "/calibration.json");
  }
  std::ofstream actor(out_dir + "/actor.csv");
  actor << "frame,t_ns,x_m,y_m,z_m,heading_rad,phase_rad\n";
  for (int f = 0; f < frames; ++f) {
    const StudioActorState s = StudioActorAt(f / spec.fps);
    char line[200];
    std::snprintf(line, sizeof(line), "%d,%lld,%.9f,%.9f,%.9f,%.9f,%.9f\n", f, static_cast<long long>(std::llround(f / spec.fps * 1e9)),
                  s.ground_m.x(), s.ground_m.y(), s.ground_m.z(), s.heading_rad, s.phase_rad);
    actor << line;
  }
  if (!actor) return absl::InternalError("cannot write " + out_dir + "/actor.csv");
  for (const StudioCamera& cam : cams) {
    const std::string dir = out_dir + "/" + cam.id;
    if (const std::string why = internal::MakeDirs(dir); !why.empty()) return absl::InternalError(why);
    StudioView empty = RenderStudioBackground(cam, effects, seed);
    if (!cv::imwrite(dir + "/background.png", cv::Mat(empty.height, empty.width, CV_8UC3, empty.bgr.data()))) {
      return absl::InternalError("cannot write " + dir + "/background.png");
    }
    for (int f = 0; f < frames; ++f) {
      StudioView view = RenderStudioView(cam, effects, seed, f, f / spec.fps, spec.actor);
      char name[32];
      std::snprintf(name, sizeof(name), "%04d.png", f);
      const cv::Mat image(view.height, view.width, CV_8UC3, view.bgr.data());
      const cv::Mat mask(view.height, view.width, CV_8UC1, view.silhouette.data());
      if (!cv::imwrite(dir + "/image_" + name, image) || !cv::imwrite(dir + "/mask_" + name, mask)) {
        return absl::InternalError("cannot write " + dir + "/image_" + name);
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace ave::sim
