#include "viewer_client/render/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <set>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <epoxy/gl.h>

#include "model_store/geometry/camera.h"
#include "viewer_client/render/shader_program.h"

namespace ave::viewer {
namespace {

// Texture units of the deferred passes.
constexpr GLint kGbufferColorUnit = 0;
constexpr GLint kGbufferNormalUnit = 1;
constexpr GLint kGbufferDepthUnit = 2;
constexpr GLint kVideoUnit = 3;
constexpr GLint kShadowUnit = 4;
constexpr GLint kLiveUnit = 5;
constexpr GLint kRetainedUnit = 6;
constexpr GLint kFadeUnit = 7;
// Depth bias of the shadow pass, in addition to the normal offset of the projector shader: the
// slope term absorbs the depth change across one texel on grazing ground (paper section 8).
constexpr float kShadowSlopeBias = 1.5f;
constexpr float kShadowConstantBias = 2.0f;
// Normal offset for the shadow lookup, in shadow-map texels at the fragment's distance.
constexpr float kNormalOffsetTexels = 1.0f;
constexpr float kHighlightLineWidth = 3.0f;
// Retained snapshots fainter than this are not drawn (one 8-bit step).
constexpr double kMinFade = 1.0 / 256;
// Retained weights are scaled by fade^kNewerWins so the newest snapshot dominates an overlap.
constexpr double kNewerWins = 16;

struct Vertex {
  float position[3];
  float normal[3];
  float color[3];
};

struct LineVertex {
  float position[3];
  float color[3];
};

using GlMatrix = std::array<float, 16>;

enum class Pass { kUpload, kShadow, kGbuffer, kProjector, kResolve, kLines };

// Every fixed-function state change of the renderer is here (STYLE habit 6).
void ApplyPassState(Pass pass, bool blend = false) {
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_CLAMP);
  glDisable(GL_POLYGON_OFFSET_FILL);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  switch (pass) {
    case Pass::kUpload:
      glDisable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      break;
    case Pass::kShadow:
      glDisable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
      glEnable(GL_POLYGON_OFFSET_FILL);
      glPolygonOffset(kShadowSlopeBias, kShadowConstantBias);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      break;
    case Pass::kGbuffer:
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
      break;
    case Pass::kProjector:
      // Back faces of the frustum volume cover every pixel whose view ray meets the volume exactly
      // once, with the eye inside or outside it; depth clamping keeps far faces beyond the view's
      // far plane.
      glEnable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
      glEnable(GL_CULL_FACE);
      glCullFace(GL_FRONT);
      glEnable(GL_DEPTH_CLAMP);
      if (blend) {
        glEnable(GL_BLEND);
        glBlendEquation(GL_FUNC_ADD);
        glBlendFunc(GL_ONE, GL_ONE);
      }
      break;
    case Pass::kResolve:
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_ALWAYS);
      glDepthMask(GL_TRUE);
      break;
    case Pass::kLines:
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_LEQUAL);
      glDepthMask(GL_TRUE);
      break;
  }
}

// Restores the caller's framebuffer bindings and viewport after internal passes.
class FramebufferGuard {
 public:
  FramebufferGuard() {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &draw_);
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_);
    glGetIntegerv(GL_VIEWPORT, viewport_);
  }
  ~FramebufferGuard() {
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(draw_));
    glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(read_));
    glViewport(viewport_[0], viewport_[1], viewport_[2], viewport_[3]);
  }
  GLuint draw() const { return static_cast<GLuint>(draw_); }

 private:
  GLint draw_ = 0, read_ = 0;
  GLint viewport_[4] = {0, 0, 0, 0};
};

absl::Status CheckGl(const char* where) {
  const GLenum error = glGetError();
  if (error == GL_NO_ERROR) return absl::OkStatus();
  while (glGetError() != GL_NO_ERROR) {
  }
  char hex[16];
  std::snprintf(hex, sizeof(hex), "0x%04x", static_cast<unsigned>(error));
  return absl::InternalError(std::string(where) + ": GL error " + hex);
}

absl::Status CheckFramebuffer(GLenum target, const char* what) {
  const GLenum status = glCheckFramebufferStatus(target);
  if (status == GL_FRAMEBUFFER_COMPLETE) return absl::OkStatus();
  return absl::InternalError(std::string(what) + ": framebuffer incomplete (status " + std::to_string(status) + ")");
}

struct MeshBuffers {
  GLuint vao = 0, vbo = 0, ebo = 0;
  GLsizei count = 0;  // indices (indexed) or vertices

  void Create(bool with_normals, bool indexed) {
    glGenVertexArrays(1, &vao);
    glGenBuffers(1, &vbo);
    glBindVertexArray(vao);
    glBindBuffer(GL_ARRAY_BUFFER, vbo);
    if (indexed) {
      glGenBuffers(1, &ebo);
      glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo);
    }
    const GLsizei stride = with_normals ? sizeof(Vertex) : sizeof(LineVertex);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(0));
    if (with_normals) {
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(Vertex, normal)));
      glEnableVertexAttribArray(2);
      glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(Vertex, color)));
    } else {
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<void*>(offsetof(LineVertex, color)));
    }
    glBindVertexArray(0);
  }
  void Destroy() {
    if (ebo) glDeleteBuffers(1, &ebo);
    if (vbo) glDeleteBuffers(1, &vbo);
    if (vao) glDeleteVertexArrays(1, &vao);
  }
  template <typename T>
  void Upload(const std::vector<T>& vertices, GLenum usage) {
    glBindBuffer(GL_ARRAY_BUFFER, vbo);
    glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(T), vertices.data(), usage);
    count = static_cast<GLsizei>(vertices.size());
  }
  void Draw(GLenum mode, GLint first = 0, GLsizei n = -1) const {
    if (count == 0) return;
    glBindVertexArray(vao);
    if (ebo) {
      glDrawElements(mode, count, GL_UNSIGNED_INT, nullptr);
    } else {
      glDrawArrays(mode, first, n < 0 ? count : n);
    }
  }
};

Vertex MakeVertex(const Eigen::Vector3f& p, const Eigen::Vector3f& n, const Eigen::Vector3f& c) {
  return Vertex{{p.x(), p.y(), p.z()}, {n.x(), n.y(), n.z()}, {c.x(), c.y(), c.z()}};
}

LineVertex MakeLineVertex(const Eigen::Vector3d& p, const Eigen::Vector3f& c) {
  return LineVertex{{static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())},
                    {c.x(), c.y(), c.z()}};
}

// A triangle wound counter-clockwise as seen from the side `outward` points to.
template <typename V, typename Make>
void AppendOrientedTriangle(const Eigen::Vector3d& a, Eigen::Vector3d b, Eigen::Vector3d c,
                            const Eigen::Vector3d& outward, std::vector<V>& out, Make make) {
  if ((b - a).cross(c - a).dot(outward) < 0) std::swap(b, c);
  out.push_back(make(a));
  out.push_back(make(b));
  out.push_back(make(c));
}

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

// The four image corners of a camera at depth_m along its optical axis, NDC scaled by `scale`
// (1: the image rectangle), counter-clockwise from bottom-left.
std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              double scale, double depth_m) {
  std::array<Eigen::Vector3d, 4> corners;
  const double ndc[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector4d e = eye_from_clip * Eigen::Vector4d(scale * ndc[k][0], scale * ndc[k][1], -1, 1);
    e /= e.w();
    const Eigen::Vector3d at_depth = e.head<3>() * (depth_m / -e.z());
    corners[k] = (local_from_eye * at_depth.homogeneous()).head<3>();
  }
  return corners;
}

// Camera centre to the four image corners at depth_m along the optical axis, plus the rectangle.
std::array<Eigen::Vector3d, 16> FrustumSegments(const Projector& p, double depth_m) {
  const Eigen::Matrix4d local_from_eye = p.view.inverse();
  const std::array<Eigen::Vector3d, 4> corners = FrustumCorners(local_from_eye, p.projection.inverse(), 1, depth_m);
  const Eigen::Vector3d centre = (local_from_eye * Eigen::Vector4d(0, 0, 0, 1)).head<3>();
  std::array<Eigen::Vector3d, 16> segments;
  for (int k = 0; k < 4; ++k) {
    segments[4 * k + 0] = centre;
    segments[4 * k + 1] = corners[k];
    segments[4 * k + 2] = corners[k];
    segments[4 * k + 3] = corners[(k + 1) % 4];
  }
  return segments;
}

bool HasDistortion(const Projector& p) {
  return std::any_of(p.distortion.begin(), p.distortion.end(), [](double k) { return k != 0; });
}

// How far beyond the undistorted image the distorted frame may reach (NDC factor): the shadow map
// and the footprint are widened by it. Barrel distortion (k1 < 0) pulls a wider field into the
// frame; this bound covers |k| sums up to 0.5 (the frame corners of common wide lenses).
double DistortionMargin(const Projector& p) {
  if (!HasDistortion(p)) return 1;
  const double sum = std::abs(p.distortion[0]) + std::abs(p.distortion[1]) + std::abs(p.distortion[4]) +
                     std::abs(p.distortion[2]) + std::abs(p.distortion[3]);
  return std::clamp(1 + 2 * sum, 1.0, 2.0);
}

bool MatricesFinite(const Projector& p) {
  return p.view.allFinite() && p.projection.allFinite() && p.position.allFinite();
}

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Rendered shadow map state of one layer.
struct ShadowSlot {
  bool valid = false;
  // From the static shadow map (read back when it is rendered): the farthest surface the projector
  // sees, along its axis, and whether some texel sees nothing (sky). Bounds its footprint.
  double visible_far_m = 0;
  bool sees_void = true;
  GlMatrix clip_from_local{};
  uint64_t static_version = 0;
  uint64_t dynamic_version = 0;
};

// One layer set: a shadow-map array, and optionally a second one with dynamic models added.
struct ShadowArrays {
  GLuint static_array = 0, dynamic_array = 0;
  int layers = 0;

  // True when it reallocated (every layer's content is lost).
  bool Ensure(int needed, int size, bool with_dynamic) {
    if (needed <= layers) return false;
    for (GLuint* texture : {&static_array, &dynamic_array}) {
      if (texture == &dynamic_array && !with_dynamic) continue;
      if (*texture == 0) glGenTextures(1, texture);
      glBindTexture(GL_TEXTURE_2D_ARRAY, *texture);
      glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_DEPTH_COMPONENT32F, size, size, needed, 0, GL_DEPTH_COMPONENT, GL_FLOAT,
                   nullptr);
      // NEAREST: one depth compare per lookup; LINEAR (2x2 PCF) cost ~15% of the frame on llvmpipe.
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    }
    layers = needed;
    return true;
  }
  void Destroy() {
    const GLuint textures[] = {static_array, dynamic_array};
    glDeleteTextures(2, textures);
  }
};

// What live layer i holds.
struct LiveSlot {
  std::string camera_id;
  uint64_t image_serial = 0;
  bool has_image = false;
  double image_time_s = 0;
  ShadowSlot shadow;
  std::optional<Eigen::Matrix4d> anchor_view;  // pose at the last snapshot (or the first pose)
};

// A camera's last imagery at a pose it has left (texture retention, issue 7).
struct RetainedSnapshot {
  bool in_use = false;
  std::string camera_id;
  Projector projector;  // image_rgba empty
  double capture_time_s = 0;
  uint64_t order = 0;  // larger: newer
  ShadowSlot shadow;
};

// Per-projector matrices for one frame.
struct ProjectorGl {
  GlMatrix clip_from_local{}, shadow_clip_from_local{};
  Eigen::Matrix4d shadow_projection = Eigen::Matrix4d::Identity();  // widened by the distortion margin
  float pinhole[4] = {0, 0, 0, 0};
  float distortion[5] = {0, 0, 0, 0, 0};
  bool distorted = false;
  float normal_offset = 0;
};

ProjectorGl MakeProjectorGl(const Projector& p, int shadow_map_size) {
  ProjectorGl g;
  const double margin = DistortionMargin(p);
  Eigen::Matrix4d widen = Eigen::Matrix4d::Identity();
  widen(0, 0) = widen(1, 1) = 1 / margin;
  g.clip_from_local = ToGlArray(p.projection * p.view);
  g.shadow_projection = widen * p.projection;
  g.shadow_clip_from_local = ToGlArray(g.shadow_projection * p.view);
  g.pinhole[0] = static_cast<float>(p.projection(0, 0));
  g.pinhole[1] = static_cast<float>(p.projection(0, 2));
  g.pinhole[2] = static_cast<float>(p.projection(1, 1));
  g.pinhole[3] = static_cast<float>(p.projection(1, 2));
  for (int k = 0; k < 5; ++k) g.distortion[k] = static_cast<float>(p.distortion[k]);
  g.distorted = HasDistortion(p);
  // Metres per metre of distance covered by one shadow texel: 2 margin / (P00 * size), wider axis.
  const double texel = 2.0 * margin /
                       (std::min(std::abs(p.projection(0, 0)), std::abs(p.projection(1, 1))) * shadow_map_size);
  g.normal_offset = static_cast<float>(kNormalOffsetTexels * texel);
  return g;
}

struct Bounds {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  bool empty() const { return !(lo.array() <= hi.array()).all(); }
  void Add(const Eigen::Vector3d& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  std::array<Eigen::Vector3d, 8> Corners() const {
    std::array<Eigen::Vector3d, 8> c;
    for (int k = 0; k < 8; ++k) c[k] = Eigen::Vector3d(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
    return c;
  }
};

// The frustum volume of a projector, cut at the farthest scene point (fewer pixels to shade) and
// widened by the distortion margin: 12 triangles wound counter-clockwise from outside.
void AppendFrustumVolume(const Projector& p, const Bounds& scene, const ShadowSlot& shadow, std::vector<LineVertex>& out,
                         std::array<Eigen::Vector3d, 8>& corners_out) {
  double far_m = p.far_m;
  if (!scene.empty()) {
    double farthest = 0;
    for (const Eigen::Vector3d& c : scene.Corners()) farthest = std::max(farthest, -(p.view * c.homogeneous()).z());
    far_m = std::clamp(farthest * 1.01, p.near_m * 1.01, p.far_m);
  }
  // The static shadow map says how far the projector actually sees (dynamic models stand on the
  // static model, within that depth). Most cameras look at the ground: a much smaller footprint.
  if (shadow.valid && !shadow.sees_void) far_m = std::clamp(shadow.visible_far_m * 1.02 + 1, p.near_m * 1.01, far_m);
  const Eigen::Matrix4d local_from_eye = p.view.inverse();
  const Eigen::Matrix4d eye_from_clip = p.projection.inverse();
  const double margin = DistortionMargin(p);
  const std::array<Eigen::Vector3d, 4> near_c = FrustumCorners(local_from_eye, eye_from_clip, margin, p.near_m);
  const std::array<Eigen::Vector3d, 4> far_c = FrustumCorners(local_from_eye, eye_from_clip, margin, far_m);
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) {
    corners_out[k] = near_c[k];
    corners_out[k + 4] = far_c[k];
    centre += near_c[k] + far_c[k];
  }
  centre /= 8;
  auto make = [](const Eigen::Vector3d& q) { return MakeLineVertex(q, Eigen::Vector3f::Zero()); };
  auto quad = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
    const Eigen::Vector3d outward = 0.25 * (a + b + c + d) - centre;
    AppendOrientedTriangle(a, b, c, outward, out, make);
    AppendOrientedTriangle(a, c, d, outward, out, make);
  };
  quad(near_c[0], near_c[1], near_c[2], near_c[3]);
  quad(far_c[0], far_c[1], far_c[2], far_c[3]);
  for (int k = 0; k < 4; ++k) quad(near_c[k], near_c[(k + 1) % 4], far_c[(k + 1) % 4], far_c[k]);
}

// False when all eight corners lie outside one clip plane of the view (the volume cannot show).
bool VolumeMayBeVisible(const std::array<Eigen::Vector3d, 8>& corners, const Eigen::Matrix4d& clip_from_local) {
  std::array<Eigen::Vector4d, 8> c;
  for (int k = 0; k < 8; ++k) c[k] = clip_from_local * corners[k].homogeneous();
  for (int axis = 0; axis < 3; ++axis) {
    for (double sign : {-1.0, 1.0}) {
      if (std::all_of(c.begin(), c.end(), [&](const Eigen::Vector4d& q) { return sign * q[axis] > q.w(); })) return false;
    }
  }
  return true;
}

// A run of the static mesh's (reordered) index buffer whose triangles lie in one cell of a grid
// over the model's footprint, with the box of its vertices: views draw only the chunks their
// frustum may see (llvmpipe is geometry-bound on the static model: every triangle drawn costs
// vertex shading and setup even when it lands off screen).
struct MeshChunk {
  size_t first_index = 0, index_count = 0;
  Bounds bounds;
};

// Reorders `indices` (triangles) by grid cell over the x-y box of `positions`, cells of about
// kTrianglesPerChunk triangles; returns the chunks in index-buffer order.
constexpr size_t kTrianglesPerChunk = 1024;
std::vector<MeshChunk> SortIntoChunks(const std::vector<Eigen::Vector3f>& positions, const Bounds& box,
                                      std::vector<uint32_t>& indices) {
  const size_t triangles = indices.size() / 3;
  if (triangles == 0 || box.empty()) return {};
  const int cells = std::clamp(static_cast<int>(std::sqrt(static_cast<double>(triangles) / kTrianglesPerChunk)), 1, 32);
  const Eigen::Vector3d extent = (box.hi - box.lo).cwiseMax(1e-9);
  std::vector<int> cell_of(triangles);
  std::vector<size_t> per_cell(static_cast<size_t>(cells) * cells + 1, 0);
  for (size_t t = 0; t < triangles; ++t) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) centroid += positions[indices[3 * t + k]].cast<double>() / 3;
    const int cx = std::clamp(static_cast<int>((centroid.x() - box.lo.x()) / extent.x() * cells), 0, cells - 1);
    const int cy = std::clamp(static_cast<int>((centroid.y() - box.lo.y()) / extent.y() * cells), 0, cells - 1);
    cell_of[t] = cy * cells + cx;
    ++per_cell[cell_of[t] + 1];
  }
  for (size_t c = 1; c < per_cell.size(); ++c) per_cell[c] += per_cell[c - 1];  // first triangle of each cell
  std::vector<MeshChunk> chunks(static_cast<size_t>(cells) * cells);
  std::vector<size_t> next(per_cell.begin(), per_cell.end() - 1);
  std::vector<uint32_t> sorted(indices.size());
  for (size_t t = 0; t < triangles; ++t) {  // stable: the mesh's own order within a cell
    const size_t slot = next[cell_of[t]]++;
    MeshChunk& chunk = chunks[cell_of[t]];
    for (int k = 0; k < 3; ++k) {
      sorted[3 * slot + k] = indices[3 * t + k];
      chunk.bounds.Add(positions[indices[3 * t + k]].cast<double>());
    }
  }
  for (size_t c = 0; c < chunks.size(); ++c) {
    chunks[c].first_index = 3 * per_cell[c];
    chunks[c].index_count = 3 * (per_cell[c + 1] - per_cell[c]);
  }
  std::erase_if(chunks, [](const MeshChunk& c) { return c.index_count == 0; });
  indices = std::move(sorted);
  return chunks;
}

// An inward-facing dome (elevation -10 to 90 degrees): sky marker colour r < 0.
std::vector<Vertex> SkyDome(const Eigen::Vector3d& centre, double radius_m) {
  constexpr int kRings = 10, kSegments = 32;
  std::vector<Vertex> out;
  auto point = [&](int ring, int seg) {
    const double elevation = (-10.0 + 100.0 * ring / kRings) * M_PI / 180;
    const double azimuth = 2 * M_PI * seg / kSegments;
    return Eigen::Vector3d(centre + radius_m * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                                               std::cos(elevation) * std::sin(azimuth), std::sin(elevation)));
  };
  const Eigen::Vector3f sky(-1, -1, -1);
  auto make = [&](const Eigen::Vector3d& p) {
    return MakeVertex(p.cast<float>(), (centre - p).normalized().cast<float>(), sky);
  };
  for (int ring = 0; ring < kRings; ++ring) {
    for (int seg = 0; seg < kSegments; ++seg) {
      const Eigen::Vector3d a = point(ring, seg), b = point(ring, seg + 1), c = point(ring + 1, seg + 1),
                            d = point(ring + 1, seg);
      const Eigen::Vector3d inward = centre - 0.25 * (a + b + c + d);
      AppendOrientedTriangle(a, b, c, inward, out, make);
      if (ring + 1 < kRings) AppendOrientedTriangle(a, c, d, inward, out, make);
    }
  }
  return out;
}

GLuint MakeTexture2D(GLenum internal_format, GLenum format, GLenum type, int width, int height) {
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  glTexImage2D(GL_TEXTURE_2D, 0, internal_format, width, height, 0, format, type, nullptr);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return texture;
}

// Layers grow in steps of this many (a reallocation copies the old layers).
constexpr int kLayerStep = 4;

GLuint MakeVideoArray(int width, int height, int layers) {
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D_ARRAY, texture);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA8, width, height, layers, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return texture;
}

// Uniform locations by name, looked up once.
class Uniforms {
 public:
  Uniforms() = default;
  Uniforms(GLuint program, std::initializer_list<const char*> names) {
    for (const char* name : names) locations_.emplace_back(name, glGetUniformLocation(program, name));
  }
  GLint operator[](std::string_view name) const {
    for (const auto& [n, location] : locations_) {
      if (n == name) return location;
    }
    return -1;
  }

 private:
  std::vector<std::pair<std::string_view, GLint>> locations_;
};

}  // namespace

struct Renderer::Impl {
  RendererOptions options;
  GLuint gbuffer_program = 0, shadow_program = 0, line_program = 0, projector_program = 0;
  // Resolve variants, index any_live + 2 * any_retained (resolve.frag.glsl: LIVE, RETAINED).
  std::array<GLuint, 4> resolve_programs{};
  Uniforms gbuffer_u, projector_u;
  std::array<Uniforms, 4> resolve_u;
  GLint shadow_clip_from_local = -1, line_clip_from_local = -1;

  MeshBuffers static_mesh, dynamic_mesh, sky_mesh, lines, volumes;
  std::vector<MeshChunk> static_chunks;  // static_mesh's index buffer, by grid cell
  GLuint empty_vao = 0;
  GLuint video_array = 0, retained_video_array = 0, scratch_texture = 0;
  int video_layers = 0, retained_video_layers = 0;
  int scratch_width = 0, scratch_height = 0;
  ShadowArrays live_shadows, retained_shadows;
  GLuint fbo_video_src = 0, fbo_video_dst = 0, fbo_shadow_src = 0, fbo_shadow_dst = 0;
  // Deferred targets, framebuffer-sized: G-buffer (colour + kind, normal, depth) and accumulation
  // (live, retained, retained fade).
  GLuint fbo_gbuffer = 0, fbo_accum = 0;
  GLuint gbuffer_color = 0, gbuffer_normal = 0, gbuffer_depth = 0, accum_live = 0, accum_retained = 0, accum_fade = 0;
  int target_width = 0, target_height = 0;
  float max_line_width = 1;

  std::vector<Projector> projectors;  // image_rgba cleared: only valid during SetProjectors
  std::vector<std::array<Eigen::Vector3d, 16>> frustums;
  std::array<LiveSlot, kMaxProjectors> slots;
  std::vector<RetainedSnapshot> retained;
  uint64_t snapshot_counter = 0;
  std::set<std::string> stale;
  std::optional<double> clock_s;
  double created_s = SteadySeconds();
  uint64_t static_version = 1, dynamic_version = 1;
  std::vector<Vertex> dynamic_vertices;
  std::vector<LineVertex> path_vertices;
  std::vector<float> shadow_readback;
  Bounds static_bounds, dynamic_bounds;
  RenderStats stats;

  ~Impl() {
    for (MeshBuffers* m : {&static_mesh, &dynamic_mesh, &sky_mesh, &lines, &volumes}) m->Destroy();
    glDeleteVertexArrays(1, &empty_vao);
    live_shadows.Destroy();
    retained_shadows.Destroy();
    const GLuint textures[] = {video_array,   retained_video_array, scratch_texture, gbuffer_color, gbuffer_normal,
                               gbuffer_depth, accum_live,           accum_retained,  accum_fade};
    glDeleteTextures(9, textures);
    const GLuint fbos[] = {fbo_video_src, fbo_video_dst, fbo_shadow_src, fbo_shadow_dst, fbo_gbuffer, fbo_accum};
    glDeleteFramebuffers(6, fbos);
    for (GLuint program : {gbuffer_program, shadow_program, line_program, projector_program}) {
      if (program) glDeleteProgram(program);
    }
    for (GLuint program : resolve_programs) {
      if (program) glDeleteProgram(program);
    }
  }

  double Now() const { return clock_s ? *clock_s : SteadySeconds() - created_s; }

  double Fade(double capture_time_s) const {
    const double half_life = options.display.retention_half_life_s;
    if (half_life <= 0) return 0;
    return std::pow(0.5, std::max(0.0, Now() - capture_time_s) / half_life);
  }

  absl::Status EnsureTargets(int width, int height) {
    if (width == target_width && height == target_height) return absl::OkStatus();
    const GLuint old[] = {gbuffer_color, gbuffer_normal, gbuffer_depth, accum_live, accum_retained, accum_fade};
    glDeleteTextures(6, old);
    gbuffer_color = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
    gbuffer_normal = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
    gbuffer_depth = MakeTexture2D(GL_DEPTH_COMPONENT32F, GL_DEPTH_COMPONENT, GL_FLOAT, width, height);
    accum_live = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
    accum_retained = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
    accum_fade = MakeTexture2D(GL_R32F, GL_RED, GL_FLOAT, width, height);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_gbuffer);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, gbuffer_color, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, gbuffer_normal, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, gbuffer_depth, 0);
    const GLenum gbuffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(2, gbuffers);
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "G-buffer"); !s.ok()) return s;
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_accum);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, accum_live, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, accum_retained, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT2, GL_TEXTURE_2D, accum_fade, 0);
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "projector accumulation"); !s.ok()) return s;
    target_width = width;
    target_height = height;
    return CheckGl("render targets");
  }

  // Grows a video array to at least `needed` layers, keeping the frames it holds.
  absl::Status EnsureVideoLayers(GLuint& array, int& layers, int needed) {
    if (needed <= layers) return absl::OkStatus();
    const int lw = options.video_layer_width, lh = options.video_layer_height;
    const int grown = (needed + kLayerStep - 1) / kLayerStep * kLayerStep;
    const GLuint fresh = MakeVideoArray(lw, lh, grown);
    ApplyPassState(Pass::kUpload);
    for (int layer = 0; layer < layers; ++layer) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_video_src);
      glFramebufferTextureLayer(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, array, 0, layer);
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_video_dst);
      glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, fresh, 0, layer);
      glBlitFramebuffer(0, 0, lw, lh, 0, 0, lw, lh, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    }
    if (array != 0) glDeleteTextures(1, &array);
    array = fresh;
    layers = grown;
    return CheckGl("video layers");
  }

  absl::Status UploadFrame(int layer, const Projector& p) {
    if (absl::Status s = EnsureVideoLayers(video_array, video_layers, layer + 1); !s.ok()) return s;
    ApplyPassState(Pass::kUpload);
    const int lw = options.video_layer_width, lh = options.video_layer_height;
    if (p.image_width == lw && p.image_height == lh) {
      glBindTexture(GL_TEXTURE_2D_ARRAY, video_array);
      glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, lw, lh, 1, GL_RGBA, GL_UNSIGNED_BYTE, p.image_rgba.data());
      return CheckGl("upload frame");
    }
    // Other sizes: upload as is, then resample into the layer. Rows stay top first in both.
    glBindTexture(GL_TEXTURE_2D, scratch_texture);
    if (p.image_width != scratch_width || p.image_height != scratch_height) {
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, p.image_width, p.image_height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
      scratch_width = p.image_width;
      scratch_height = p.image_height;
    }
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, p.image_width, p.image_height, GL_RGBA, GL_UNSIGNED_BYTE,
                    p.image_rgba.data());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_video_src);
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, scratch_texture, 0);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_video_dst);
    glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, video_array, 0, layer);
    if (absl::Status s = CheckFramebuffer(GL_READ_FRAMEBUFFER, "frame upload source"); !s.ok()) return s;
    if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "frame upload layer"); !s.ok()) return s;
    glBlitFramebuffer(0, 0, p.image_width, p.image_height, 0, 0, lw, lh, GL_COLOR_BUFFER_BIT, GL_LINEAR);
    return CheckGl("resample frame");
  }

  // Keeps live layer `layer` (frame and the pose it was taken at) as a retained snapshot.
  absl::Status Snapshot(const Projector& old, const LiveSlot& slot, int layer) {
    if (options.max_retained <= 0 || options.display.retention_half_life_s <= 0) return absl::OkStatus();
    int same_camera = 0, pick = -1;
    for (const RetainedSnapshot& r : retained) same_camera += r.in_use && r.camera_id == old.camera_id;
    auto older = [&](int a, int b) { return b < 0 || retained[a].order < retained[b].order; };
    for (int k = 0; k < static_cast<int>(retained.size()); ++k) {
      const RetainedSnapshot& r = retained[k];
      if (same_camera >= options.max_retained_per_camera) {
        if (r.in_use && r.camera_id == old.camera_id && older(k, pick)) pick = k;
      } else if (!r.in_use) {
        pick = k;
        break;
      } else if (older(k, pick)) {
        pick = k;
      }
    }
    if (pick < 0) return absl::OkStatus();
    if (absl::Status s = EnsureVideoLayers(retained_video_array, retained_video_layers, pick + 1); !s.ok()) return s;
    ApplyPassState(Pass::kUpload);
    const int lw = options.video_layer_width, lh = options.video_layer_height;
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_video_src);
    glFramebufferTextureLayer(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, video_array, 0, layer);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_video_dst);
    glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, retained_video_array, 0, pick);
    glBlitFramebuffer(0, 0, lw, lh, 0, 0, lw, lh, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    RetainedSnapshot& r = retained[pick];
    r.in_use = true;
    r.camera_id = old.camera_id;
    r.projector = old;
    r.capture_time_s = slot.image_time_s;
    r.order = ++snapshot_counter;
    r.shadow = ShadowSlot();
    ++stats.retained_snapshots;
    return CheckGl("retained snapshot");
  }

  // Renders the shadow map of one layer if its projector or the geometry changed.
  // The static shadow map bound for reading: its farthest depth and whether it sees nothing somewhere.
  // Skipped (bounds from the scene box) for maps above 2048 px, where the read costs more than it saves.
  void ReadShadowExtent(const Eigen::Matrix4d& shadow_projection, ShadowSlot& slot) {
    const int size = options.shadow_map_size;
    slot.sees_void = true;
    if (size > 2048) return;
    shadow_readback.resize(static_cast<size_t>(size) * size);
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, size, size, GL_DEPTH_COMPONENT, GL_FLOAT, shadow_readback.data());
    float deepest = 0;
    bool void_seen = false;
    for (float d : shadow_readback) {
      if (d >= 1.0f) {
        void_seen = true;
      } else {
        deepest = std::max(deepest, d);
      }
    }
    const Eigen::Vector4d eye = shadow_projection.inverse() * Eigen::Vector4d(0, 0, 2.0 * deepest - 1, 1);
    slot.visible_far_m = -eye.z() / eye.w();
    slot.sees_void = void_seen;
  }

  absl::Status UpdateShadow(ShadowArrays& arrays, int layer, ShadowSlot& slot, const GlMatrix& clip_from_local,
                            const Eigen::Matrix4d& shadow_projection, bool with_dynamic, bool& state_set,
                            uint64_t& counter) {
    const int size = options.shadow_map_size;
    const bool static_dirty =
        !slot.valid || slot.clip_from_local != clip_from_local || slot.static_version != static_version;
    const bool dynamic_dirty = with_dynamic && (static_dirty || slot.dynamic_version != dynamic_version);
    if (!static_dirty && !dynamic_dirty) return absl::OkStatus();
    if (!state_set) {
      ApplyPassState(Pass::kShadow);
      glViewport(0, 0, size, size);
      glUseProgram(shadow_program);
      state_set = true;
    }
    glUniformMatrix4fv(shadow_clip_from_local, 1, GL_FALSE, clip_from_local.data());
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_shadow_src);
    glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, arrays.static_array, 0, layer);
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "static shadow map"); !s.ok()) return s;
    if (static_dirty) {
      glClear(GL_DEPTH_BUFFER_BIT);
      DrawStaticChunks(Eigen::Map<const Eigen::Matrix4f>(clip_from_local.data()).cast<double>());
      ++counter;
      ReadShadowExtent(shadow_projection, slot);
    }
    if (dynamic_dirty) {
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_shadow_dst);
      glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, arrays.dynamic_array, 0, layer);
      if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "dynamic shadow map"); !s.ok()) return s;
      glBlitFramebuffer(0, 0, size, size, 0, 0, size, size, GL_DEPTH_BUFFER_BIT, GL_NEAREST);
      dynamic_mesh.Draw(GL_TRIANGLES);
      ++stats.dynamic_shadow_updates;
    }
    slot.valid = true;
    slot.clip_from_local = clip_from_local;
    slot.static_version = static_version;
    slot.dynamic_version = dynamic_version;
    return absl::OkStatus();
  }

  bool LiveActive(size_t i) const { return projectors[i].enabled && slots[i].has_image; }
  bool RetainedActive(const RetainedSnapshot& r) const { return r.in_use && Fade(r.capture_time_s) >= kMinFade; }

  absl::Status UpdateShadowMaps() {
    const int size = options.shadow_map_size;
    const bool with_dynamic = options.dynamic_objects_cast_shadows;
    if (live_shadows.Ensure(std::max<int>(1, static_cast<int>(projectors.size())), size, with_dynamic)) {
      for (LiveSlot& slot : slots) slot.shadow.valid = false;
    }
    bool state_set = false;
    for (size_t i = 0; i < projectors.size(); ++i) {
      if (!LiveActive(i)) continue;
      const ProjectorGl g = MakeProjectorGl(projectors[i], size);
      if (absl::Status s = UpdateShadow(live_shadows, static_cast<int>(i), slots[i].shadow, g.shadow_clip_from_local,
                                        g.shadow_projection, with_dynamic, state_set, stats.shadow_map_renders);
          !s.ok()) {
        return s;
      }
    }
    // Retained snapshots see the static model only: their shadow maps never need redoing for movers.
    int retained_needed = 0;
    for (size_t k = 0; k < retained.size(); ++k) {
      if (RetainedActive(retained[k])) retained_needed = static_cast<int>(k) + 1;
    }
    if (retained_needed > 0 && retained_shadows.Ensure(retained_needed, size, false)) {
      for (RetainedSnapshot& r : retained) r.shadow.valid = false;
    }
    for (size_t k = 0; k < retained.size(); ++k) {
      RetainedSnapshot& r = retained[k];
      if (!RetainedActive(r)) continue;
      const ProjectorGl g = MakeProjectorGl(r.projector, size);
      if (absl::Status s = UpdateShadow(retained_shadows, static_cast<int>(k), r.shadow, g.shadow_clip_from_local,
                                        g.shadow_projection, false, state_set, stats.retained_shadow_renders);
          !s.ok()) {
        return s;
      }
    }
    return CheckGl("shadow maps");
  }

  Bounds SceneBounds() const {
    Bounds b = static_bounds;
    if (!dynamic_bounds.empty()) {
      b.Add(dynamic_bounds.lo);
      b.Add(dynamic_bounds.hi);
    }
    if (options.display.sky && sky_mesh.count > 0) {
      const auto [centre, radius] = SkyPlacement();
      b.Add(centre - Eigen::Vector3d::Constant(radius));
      b.Add(centre + Eigen::Vector3d::Constant(radius));
    }
    return b;
  }

  std::pair<Eigen::Vector3d, double> SkyPlacement() const {
    if (static_bounds.empty()) return {Eigen::Vector3d::Zero(), std::max(100.0, options.sky_radius_m)};
    const Eigen::Vector3d mid = 0.5 * (static_bounds.lo + static_bounds.hi);
    const Eigen::Vector3d centre(mid.x(), mid.y(), static_bounds.lo.z());
    const double radius = options.sky_radius_m > 0
                              ? options.sky_radius_m
                              : std::max(100.0, 1.2 * 0.5 * (static_bounds.hi - static_bounds.lo).norm());
    return {centre, radius};
  }

  void DrawGbuffer(const View& view) {
    ApplyPassState(Pass::kGbuffer);
    glUseProgram(gbuffer_program);
    const Uniforms& u = gbuffer_u;
    glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    const Eigen::Vector3f sun = options.sun_direction.normalized();
    glUniform3f(u["u_sun_direction"], sun.x(), sun.y(), sun.z());
    glUniform1f(u["u_ambient"], options.ambient);
    glUniform1f(u["u_diffuse"], options.diffuse);
    glUniform3f(u["u_sky_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
    DrawStaticChunks(view.projection * view.view);
    glEnable(GL_CULL_FACE);
    glCullFace(GL_BACK);
    dynamic_mesh.Draw(GL_TRIANGLES);
    if (options.display.sky) sky_mesh.Draw(GL_TRIANGLES);
  }

  // The chunks of the static model that may show in a view with this matrix, consecutive ones
  // merged into one draw call.
  void DrawStaticChunks(const Eigen::Matrix4d& clip_from_local) {
    if (static_mesh.count == 0) return;
    glBindVertexArray(static_mesh.vao);
    size_t run_first = 0, run_count = 0;
    auto flush = [&] {
      if (run_count > 0) {
        glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(run_count), GL_UNSIGNED_INT,
                       reinterpret_cast<void*>(run_first * sizeof(uint32_t)));
      }
      run_count = 0;
    };
    for (const MeshChunk& chunk : static_chunks) {
      if (!VolumeMayBeVisible(chunk.bounds.Corners(), clip_from_local)) {
        ++stats.chunks_culled;
        continue;
      }
      if (run_count > 0 && run_first + run_count != chunk.first_index) flush();
      if (run_count == 0) run_first = chunk.first_index;
      run_count += chunk.index_count;
    }
    flush();
  }

  void BindProjectorInputs(const View& view) {
    glUseProgram(projector_program);
    const Uniforms& u = projector_u;
    glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
    glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
    glUniform1i(u["u_video"], kVideoUnit);
    glUniform1i(u["u_shadow"], kShadowUnit);
    const Viewport& v = view.viewport;
    const Eigen::Matrix4d clip_from_local = view.projection * view.view;
    glUniformMatrix4fv(u["u_view_clip_from_local"], 1, GL_FALSE, ToGlArray(clip_from_local).data());
    // Window x, y (pixels of the framebuffer) to the view's NDC; z stays NDC (the shader's 2 d - 1).
    Eigen::Matrix4d ndc_from_window = Eigen::Matrix4d::Identity();
    ndc_from_window(0, 0) = 2.0 / v.width;
    ndc_from_window(0, 3) = -1 - 2.0 * v.x / v.width;
    ndc_from_window(1, 1) = 2.0 / v.height;
    ndc_from_window(1, 3) = -1 - 2.0 * v.y / v.height;
    const Eigen::Matrix4d local_from_window = clip_from_local.inverse() * ndc_from_window;
    glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(local_from_window).data());
    const DisplayOptions& display = options.display;
    glUniform1f(u["u_feather"], static_cast<float>(display.seam_feather));
    glUniform1i(u["u_best_view"], display.overlap == OverlapPolicy::kBestView ? 1 : 0);
    BindTexture(kGbufferNormalUnit, GL_TEXTURE_2D, gbuffer_normal);
    BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, gbuffer_depth);
  }

  static void BindTexture(GLint unit, GLenum target, GLuint texture) {
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(target, texture);
    glActiveTexture(GL_TEXTURE0);
  }

  void DrawProjectorPass(const Projector& p, int layer, GLint first_vertex, bool last_wins, float fade,
                         float weight_scale) {
    const Uniforms& u = projector_u;
    const ProjectorGl g = MakeProjectorGl(p, options.shadow_map_size);
    glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, g.clip_from_local.data());
    glUniformMatrix4fv(u["u_shadow_clip_from_local"], 1, GL_FALSE, g.shadow_clip_from_local.data());
    glUniform1f(u["u_shadow_widen"], static_cast<float>(1 / DistortionMargin(p)));
    glUniform3f(u["u_projector_position"], static_cast<float>(p.position.x()), static_cast<float>(p.position.y()),
                static_cast<float>(p.position.z()));
    glUniform4fv(u["u_pinhole"], 1, g.pinhole);
    glUniform4f(u["u_k1_k2_p1_p2"], g.distortion[0], g.distortion[1], g.distortion[2], g.distortion[3]);
    glUniform1f(u["u_k3"], g.distortion[4]);
    glUniform1i(u["u_distorted"], g.distorted ? 1 : 0);
    glUniform1f(u["u_layer"], static_cast<float>(layer));
    glUniform1f(u["u_normal_offset"], g.normal_offset);
    glUniform1i(u["u_last_wins"], last_wins ? 1 : 0);
    glUniform1f(u["u_fade"], fade);
    glUniform1f(u["u_weight_scale"], weight_scale);
    volumes.Draw(GL_TRIANGLES, first_vertex, 36);
    ++stats.projector_passes;
  }

  void DrawLines(const View& view) {
    std::vector<LineVertex> normal_lines, highlight_lines;
    if (view.draw_frustums) {
      for (size_t i = 0; i < projectors.size(); ++i) {
        const Projector& p = projectors[i];
        if (!p.enabled) continue;
        const bool highlight = !view.highlight_camera_id.empty() && p.camera_id == view.highlight_camera_id;
        const Eigen::Vector3f color =
            highlight ? Eigen::Vector3f(0.5f * p.color + Eigen::Vector3f::Constant(0.5f)) : p.color;
        for (const Eigen::Vector3d& q : frustums[i]) {
          (highlight ? highlight_lines : normal_lines).push_back(MakeLineVertex(q, color));
        }
      }
    }
    if (view.draw_paths) normal_lines.insert(normal_lines.end(), path_vertices.begin(), path_vertices.end());
    const GLsizei normal_count = static_cast<GLsizei>(normal_lines.size());
    normal_lines.insert(normal_lines.end(), highlight_lines.begin(), highlight_lines.end());
    if (normal_lines.empty()) return;
    ApplyPassState(Pass::kLines);
    glUseProgram(line_program);
    glUniformMatrix4fv(line_clip_from_local, 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    lines.Upload(normal_lines, GL_STREAM_DRAW);
    glLineWidth(1.0f);
    if (normal_count > 0) lines.Draw(GL_LINES, 0, normal_count);
    if (!highlight_lines.empty()) {
      glLineWidth(std::min(kHighlightLineWidth, max_line_width));
      lines.Draw(GL_LINES, normal_count, static_cast<GLsizei>(highlight_lines.size()));
      glLineWidth(1.0f);
    }
  }

  void Resolve(const View& view, bool any_live, bool any_retained) {
    ApplyPassState(Pass::kResolve);
    const int variant = (any_live ? 1 : 0) + (any_retained ? 2 : 0);
    glUseProgram(resolve_programs[variant]);
    const Uniforms& u = resolve_u[variant];
    glUniform1i(u["u_gbuffer_color"], kGbufferColorUnit);
    glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
    glUniform1i(u["u_live"], kLiveUnit);
    glUniform1i(u["u_retained"], kRetainedUnit);
    glUniform1i(u["u_fade"], kFadeUnit);
    glUniform3f(u["u_clear_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
    glUniform1i(u["u_tint_by_age"], options.display.tint_by_age ? 1 : 0);
    BindTexture(kGbufferColorUnit, GL_TEXTURE_2D, gbuffer_color);
    BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, gbuffer_depth);
    BindTexture(kLiveUnit, GL_TEXTURE_2D, accum_live);
    BindTexture(kRetainedUnit, GL_TEXTURE_2D, accum_retained);
    BindTexture(kFadeUnit, GL_TEXTURE_2D, accum_fade);
    glBindVertexArray(empty_vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
  }
};

Renderer::Renderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Renderer::~Renderer() = default;
const RendererOptions& Renderer::options() const { return impl_->options; }
RenderStats Renderer::stats() const { return impl_->stats; }
void Renderer::SetClock(double now_s) { impl_->clock_s = now_s; }
std::vector<std::string> Renderer::StaleCameras() const { return {impl_->stale.begin(), impl_->stale.end()}; }

absl::Status Renderer::SetDisplayOptions(const DisplayOptions& display) {
  if (const std::string why = display.Check(); !why.empty()) {
    return absl::InvalidArgumentError("DisplayOptions: " + why);
  }
  impl_->options.display = display;
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<Renderer>> Renderer::Create(const RendererOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("RendererOptions: " + why);
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  if (major * 10 + minor < 33) {
    return absl::FailedPreconditionError("Renderer needs a current OpenGL 3.3+ core context, got " +
                                         std::to_string(major) + "." + std::to_string(minor));
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;

  struct ProgramSpec {
    GLuint* program;
    const char* vertex;
    const char* fragment;
  };
  for (const ProgramSpec& spec : {ProgramSpec{&impl->gbuffer_program, "shaders/gbuffer.vert.glsl", "shaders/gbuffer.frag.glsl"},
                                  ProgramSpec{&impl->shadow_program, "shaders/shadow.vert.glsl", "shaders/shadow.frag.glsl"},
                                  ProgramSpec{&impl->line_program, "shaders/line.vert.glsl", "shaders/line.frag.glsl"},
                                  ProgramSpec{&impl->projector_program, "shaders/projector.vert.glsl",
                                              "shaders/projector.frag.glsl"}}) {
    absl::StatusOr<GLuint> program = internal::BuildEmbeddedProgram(spec.vertex, spec.fragment);
    if (!program.ok()) return program.status();
    *spec.program = *program;
  }
  impl->gbuffer_u = Uniforms(impl->gbuffer_program, {"u_clip_from_local", "u_sun_direction", "u_ambient", "u_diffuse",
                                                     "u_sky_color"});
  impl->projector_u = Uniforms(
      impl->projector_program,
      {"u_gbuffer_normal", "u_gbuffer_depth", "u_view_clip_from_local", "u_local_from_window",
       "u_clip_from_local", "u_shadow_clip_from_local", "u_shadow_widen",
       "u_projector_position", "u_pinhole", "u_k1_k2_p1_p2", "u_k3", "u_distorted", "u_layer", "u_normal_offset",
       "u_feather", "u_best_view", "u_last_wins", "u_fade", "u_weight_scale", "u_video", "u_shadow"});
  for (int variant = 0; variant < 4; ++variant) {
    const std::string defines = std::string(variant & 1 ? "#define LIVE\n" : "") + (variant & 2 ? "#define RETAINED\n" : "");
    absl::StatusOr<GLuint> program =
        internal::BuildEmbeddedProgram("shaders/resolve.vert.glsl", "shaders/resolve.frag.glsl", defines);
    if (!program.ok()) return program.status();
    impl->resolve_programs[variant] = *program;
    impl->resolve_u[variant] = Uniforms(*program, {"u_gbuffer_color", "u_gbuffer_depth", "u_live", "u_retained",
                                                   "u_fade", "u_clear_color", "u_tint_by_age"});
  }
  impl->shadow_clip_from_local = glGetUniformLocation(impl->shadow_program, "u_clip_from_local");
  impl->line_clip_from_local = glGetUniformLocation(impl->line_program, "u_clip_from_local");

  impl->static_mesh.Create(/*with_normals=*/true, /*indexed=*/true);
  impl->dynamic_mesh.Create(/*with_normals=*/true, /*indexed=*/false);
  impl->sky_mesh.Create(/*with_normals=*/true, /*indexed=*/false);
  impl->lines.Create(/*with_normals=*/false, /*indexed=*/false);
  impl->volumes.Create(/*with_normals=*/false, /*indexed=*/false);
  glGenVertexArrays(1, &impl->empty_vao);

  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  // One layer each until frames arrive (EnsureVideoLayers grows them), so the samplers are complete.
  impl->video_array = MakeVideoArray(options.video_layer_width, options.video_layer_height, 1);
  impl->retained_video_array = MakeVideoArray(options.video_layer_width, options.video_layer_height, 1);
  impl->video_layers = impl->retained_video_layers = 1;
  impl->retained.resize(static_cast<size_t>(options.max_retained));
  glGenTextures(1, &impl->scratch_texture);
  glBindTexture(GL_TEXTURE_2D, impl->scratch_texture);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  for (GLuint* fbo : {&impl->fbo_video_src, &impl->fbo_video_dst, &impl->fbo_shadow_src, &impl->fbo_shadow_dst,
                      &impl->fbo_gbuffer, &impl->fbo_accum}) {
    glGenFramebuffers(1, fbo);
  }
  {
    FramebufferGuard guard;
    for (GLuint fbo : {impl->fbo_shadow_src, impl->fbo_shadow_dst}) {
      glBindFramebuffer(GL_FRAMEBUFFER, fbo);
      glDrawBuffer(GL_NONE);
      glReadBuffer(GL_NONE);
    }
  }
  impl->live_shadows.Ensure(1, options.shadow_map_size, options.dynamic_objects_cast_shadows);
  impl->sky_mesh.Upload(SkyDome(impl->SkyPlacement().first, impl->SkyPlacement().second), GL_STATIC_DRAW);
  GLfloat line_range[2] = {1, 1};
  glGetFloatv(GL_ALIASED_LINE_WIDTH_RANGE, line_range);
  impl->max_line_width = line_range[1];
  if (absl::Status s = CheckGl("Renderer::Create"); !s.ok()) return s;
  return std::unique_ptr<Renderer>(new Renderer(std::move(impl)));
}

absl::Status Renderer::SetStaticMesh(const TriangleMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (mesh.normals.size() != n || mesh.colors.size() != n) {
    return absl::InvalidArgumentError("SetStaticMesh: " + std::to_string(n) + " positions but " +
                                      std::to_string(mesh.normals.size()) + " normals and " +
                                      std::to_string(mesh.colors.size()) + " colors");
  }
  if (mesh.indices.size() % 3 != 0) return absl::InvalidArgumentError("SetStaticMesh: indices not a multiple of 3");
  for (size_t k = 0; k < mesh.indices.size(); ++k) {
    if (mesh.indices[k] >= n) {
      return absl::InvalidArgumentError("SetStaticMesh: index " + std::to_string(k) + " = " +
                                        std::to_string(mesh.indices[k]) + " >= vertex count " + std::to_string(n));
    }
  }
  std::vector<Vertex> vertices(n);
  Bounds bounds;
  for (size_t k = 0; k < n; ++k) {
    if (!mesh.positions[k].allFinite() || !mesh.normals[k].allFinite() || !mesh.colors[k].allFinite()) {
      return absl::InvalidArgumentError("SetStaticMesh: vertex " + std::to_string(k) + " is not finite");
    }
    vertices[k] = MakeVertex(mesh.positions[k], mesh.normals[k], mesh.colors[k].cwiseMax(0.0f));
    bounds.Add(mesh.positions[k].cast<double>());
  }
  Impl& d = *impl_;
  std::vector<uint32_t> indices = mesh.indices;
  d.static_chunks = SortIntoChunks(mesh.positions, bounds, indices);
  MeshBuffers& m = d.static_mesh;
  glBindVertexArray(m.vao);
  glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(Vertex), vertices.data(), GL_STATIC_DRAW);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, indices.size() * sizeof(uint32_t), indices.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  m.count = static_cast<GLsizei>(indices.size());
  d.static_bounds = bounds;
  const auto [centre, radius] = d.SkyPlacement();
  d.sky_mesh.Upload(SkyDome(centre, radius), GL_STATIC_DRAW);
  ++d.static_version;
  return CheckGl("SetStaticMesh");
}

absl::Status Renderer::SetProjectors(const std::vector<Projector>& projectors) {
  if (projectors.size() > static_cast<size_t>(kMaxProjectors)) {
    return absl::InvalidArgumentError("SetProjectors: " + std::to_string(projectors.size()) +
                                      " projectors, the renderer supports at most " + std::to_string(kMaxProjectors));
  }
  for (const Projector& p : projectors) {
    const std::string who = "SetProjectors: camera '" + p.camera_id + "': ";
    if (!p.color.allFinite()) return absl::InvalidArgumentError(who + "color must be finite");
    if (!(p.near_m > 0) || !(p.far_m > p.near_m) || !std::isfinite(p.far_m)) {
      return absl::InvalidArgumentError(who + "needs 0 < near_m < far_m");
    }
    if (!std::all_of(p.distortion.begin(), p.distortion.end(), [](double k) { return std::isfinite(k); })) {
      return absl::InvalidArgumentError(who + "distortion must be finite");
    }
    if (MatricesFinite(p) &&
        (std::abs(p.projection.determinant()) < 1e-300 || std::abs(p.view.determinant()) < 1e-12)) {
      return absl::InvalidArgumentError(who + "view and projection must be invertible");
    }
    if (!p.image_rgba.empty()) {
      if (p.image_width <= 0 || p.image_height <= 0 || p.image_width > 16384 || p.image_height > 16384) {
        return absl::InvalidArgumentError(who + "image size " + std::to_string(p.image_width) + "x" +
                                          std::to_string(p.image_height) + " must be in 1..16384");
      }
      const size_t expected = static_cast<size_t>(p.image_width) * p.image_height * 4;
      if (p.image_rgba.size() != expected) {
        return absl::InvalidArgumentError(who + "image has " + std::to_string(p.image_rgba.size()) +
                                          " bytes, RGBA8 " + std::to_string(p.image_width) + "x" +
                                          std::to_string(p.image_height) + " needs " + std::to_string(expected));
      }
    }
  }
  Impl& d = *impl_;
  FramebufferGuard guard;
  std::vector<Projector> previous = std::move(d.projectors);
  d.projectors.clear();
  d.frustums.clear();
  const double turn_cos = std::cos(d.options.retention_turn_deg * M_PI / 180);
  for (size_t i = 0; i < projectors.size(); ++i) {
    const Projector* old = i < previous.size() ? &previous[i] : nullptr;
    LiveSlot& slot = d.slots[i];
    if (slot.camera_id != projectors[i].camera_id) {
      slot = LiveSlot();
      slot.camera_id = projectors[i].camera_id;
      old = nullptr;
    }
    Projector p = projectors[i];
    if (!MatricesFinite(p)) {
      // A pose with NaNs: the frame is ignored; the camera keeps its last good state, marked stale.
      d.stale.insert(p.camera_id);
      if (old != nullptr) {
        p = *old;
      } else {
        p.view = p.projection = Eigen::Matrix4d::Identity();
        p.position.setZero();
        p.enabled = false;
      }
      p.image_rgba = {};
    } else {
      d.stale.erase(p.camera_id);
      if (slot.has_image && old != nullptr && slot.anchor_view) {
        const Eigen::Matrix3d r_new = p.view.topLeftCorner<3, 3>(), r_anchor = slot.anchor_view->topLeftCorner<3, 3>();
        const Eigen::Vector3d c_new = -r_new.transpose() * p.view.topRightCorner<3, 1>();
        const Eigen::Vector3d c_anchor = -r_anchor.transpose() * slot.anchor_view->topRightCorner<3, 1>();
        const double axis_cos = r_new.row(2).dot(r_anchor.row(2));
        if (axis_cos < turn_cos || (c_new - c_anchor).norm() > d.options.retention_move_m) {
          if (absl::Status s = d.Snapshot(*old, slot, static_cast<int>(i)); !s.ok()) return s;
          slot.anchor_view = p.view;
        }
      }
      if (!slot.anchor_view) slot.anchor_view = p.view;
    }
    if (p.enabled && !p.image_rgba.empty() && (!slot.has_image || slot.image_serial != p.image_serial)) {
      if (absl::Status s = d.UploadFrame(static_cast<int>(i), p); !s.ok()) {
        return absl::InternalError("SetProjectors: camera '" + p.camera_id + "': " + std::string(s.message()));
      }
      slot.has_image = true;
      slot.image_serial = p.image_serial;
      slot.image_time_s = d.Now();
      ++d.stats.video_uploads;
    }
    d.frustums.push_back(FrustumSegments(p, d.options.frustum_depth_m));
    p.image_rgba = {};
    d.projectors.push_back(std::move(p));
  }
  for (size_t i = projectors.size(); i < d.slots.size(); ++i) d.slots[i] = LiveSlot();
  return CheckGl("SetProjectors");
}

absl::Status Renderer::SetDynamicObjects(const std::vector<DynamicBox>& boxes) {
  std::vector<DynamicModel> models;
  models.reserve(boxes.size());
  for (const DynamicBox& b : boxes) models.push_back(DynamicModel{b.base, b.heading_rad, b.size, b.color, ModelShape::kCuboid});
  return SetDynamicModels(models);
}

absl::Status Renderer::SetDynamicModels(const std::vector<DynamicModel>& models) {
  std::vector<Vertex> vertices;
  vertices.reserve(models.size() * 30);
  Bounds bounds;
  for (size_t k = 0; k < models.size(); ++k) {
    const DynamicModel& m = models[k];
    if (!m.base.allFinite() || !std::isfinite(m.heading_rad) || !m.size.allFinite() || !m.color.allFinite() ||
        (m.size.array() <= 0).any()) {
      return absl::InvalidArgumentError("SetDynamicObjects: model " + std::to_string(k) +
                                        " needs finite values and a positive size");
    }
    AppendModelVertices(m, vertices);
    bounds.Add(m.base - Eigen::Vector3d(m.size.x() + m.size.y(), m.size.x() + m.size.y(), 0));
    bounds.Add(m.base + Eigen::Vector3d(m.size.x() + m.size.y(), m.size.x() + m.size.y(), m.size.z()));
  }
  Impl& d = *impl_;
  const bool same = vertices.size() == d.dynamic_vertices.size() &&
                    (vertices.empty() ||
                     std::memcmp(vertices.data(), d.dynamic_vertices.data(), vertices.size() * sizeof(Vertex)) == 0);
  if (same) return absl::OkStatus();
  d.dynamic_mesh.Upload(vertices, GL_DYNAMIC_DRAW);
  d.dynamic_vertices = std::move(vertices);
  d.dynamic_bounds = bounds;
  ++d.dynamic_version;
  return CheckGl("SetDynamicObjects");
}

absl::Status Renderer::SetPaths(const std::vector<Polyline>& paths) {
  std::vector<LineVertex> vertices;
  for (size_t k = 0; k < paths.size(); ++k) {
    const Polyline& path = paths[k];
    if (!path.color.allFinite()) return absl::InvalidArgumentError("SetPaths: path " + std::to_string(k) + " color");
    for (size_t j = 0; j + 1 < path.points.size(); ++j) {
      if (!path.points[j].allFinite() || !path.points[j + 1].allFinite()) {
        return absl::InvalidArgumentError("SetPaths: path " + std::to_string(k) + " point " + std::to_string(j) +
                                          " is not finite");
      }
      vertices.push_back(MakeLineVertex(path.points[j], path.color));
      vertices.push_back(MakeLineVertex(path.points[j + 1], path.color));
    }
  }
  impl_->path_vertices = std::move(vertices);
  return absl::OkStatus();
}

absl::Status Renderer::Render(const std::vector<View>& views, int framebuffer_width, int framebuffer_height) {
  if (framebuffer_width <= 0 || framebuffer_height <= 0) {
    return absl::InvalidArgumentError("Render: framebuffer size must be positive");
  }
  for (size_t k = 0; k < views.size(); ++k) {
    const Viewport& v = views[k].viewport;
    if (v.width <= 0 || v.height <= 0 || v.x < 0 || v.y < 0 || v.x + v.width > framebuffer_width ||
        v.y + v.height > framebuffer_height) {
      return absl::InvalidArgumentError("Render: view " + std::to_string(k) + " viewport (" + std::to_string(v.x) +
                                        ", " + std::to_string(v.y) + ", " + std::to_string(v.width) + "x" +
                                        std::to_string(v.height) + ") is not inside the framebuffer");
    }
    if (!views[k].view.allFinite() || !views[k].projection.allFinite()) {
      return absl::InvalidArgumentError("Render: view " + std::to_string(k) + " has non-finite matrices");
    }
  }
  Impl& d = *impl_;
  FramebufferGuard guard;
  const GLuint target = guard.draw();
  if (absl::Status s = d.EnsureTargets(framebuffer_width, framebuffer_height); !s.ok()) return s;
  if (absl::Status s = d.UpdateShadowMaps(); !s.ok()) return s;

  // Frustum volumes of every active projector (live, then retained), 36 vertices each.
  const Bounds scene = d.SceneBounds();
  struct ProjectorPass {
    const Projector* projector;
    int layer;
    bool retained;
    float fade;
    std::array<Eigen::Vector3d, 8> corners;
  };
  std::vector<ProjectorPass> passes;
  std::vector<LineVertex> volume_vertices;
  for (size_t i = 0; i < d.projectors.size(); ++i) {
    if (!d.LiveActive(i)) continue;
    passes.push_back(ProjectorPass{&d.projectors[i], static_cast<int>(i), false, 1.0f, {}});
    AppendFrustumVolume(d.projectors[i], scene, d.slots[i].shadow, volume_vertices, passes.back().corners);
  }
  if (d.options.display.retention_half_life_s > 0) {
    for (size_t k = 0; k < d.retained.size(); ++k) {
      const RetainedSnapshot& r = d.retained[k];
      if (!d.RetainedActive(r)) continue;
      passes.push_back(ProjectorPass{&r.projector, static_cast<int>(k), true, static_cast<float>(d.Fade(r.capture_time_s)), {}});
      AppendFrustumVolume(r.projector, scene, r.shadow, volume_vertices, passes.back().corners);
    }
  }
  d.volumes.Upload(volume_vertices, GL_STREAM_DRAW);

  const bool last_wins = d.options.display.overlap == OverlapPolicy::kLastWins;
  for (const View& view : views) {
    const Viewport& v = view.viewport;
    const Eigen::Matrix4d clip_from_local = view.projection * view.view;
    glViewport(v.x, v.y, v.width, v.height);
    glScissor(v.x, v.y, v.width, v.height);

    glBindFramebuffer(GL_FRAMEBUFFER, d.fbo_gbuffer);
    ApplyPassState(Pass::kGbuffer);
    glClearColor(0, 0, 0, 0);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    d.DrawGbuffer(view);

    glBindFramebuffer(GL_FRAMEBUFFER, d.fbo_accum);
    // Only the targets this view's passes write are cleared, and only those the resolve reads.
    bool any_live = false, any_retained = false;
    std::vector<char> visible(passes.size());
    for (size_t k = 0; k < passes.size(); ++k) {
      visible[k] = VolumeMayBeVisible(passes[k].corners, clip_from_local);
      if (!visible[k]) ++d.stats.projectors_culled;
      (passes[k].retained ? any_retained : any_live) |= static_cast<bool>(visible[k]);
    }
    const GLenum none = GL_NONE;
    const GLenum all_accum[] = {any_live ? GLenum{GL_COLOR_ATTACHMENT0} : none,
                                any_retained ? GLenum{GL_COLOR_ATTACHMENT1} : none,
                                any_retained ? GLenum{GL_COLOR_ATTACHMENT2} : none};
    glDrawBuffers(3, all_accum);
    ApplyPassState(Pass::kGbuffer);
    if (any_live || any_retained) glClear(GL_COLOR_BUFFER_BIT);
    d.BindProjectorInputs(view);
    Impl::BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, d.video_array);
    Impl::BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY,
                      d.options.dynamic_objects_cast_shadows ? d.live_shadows.dynamic_array : d.live_shadows.static_array);
    const GLenum live_buffers[] = {GL_COLOR_ATTACHMENT0, GL_NONE};
    glDrawBuffers(2, live_buffers);
    ApplyPassState(Pass::kProjector, /*blend=*/!last_wins);
    bool retained_bound = false;
    for (size_t k = 0; k < passes.size(); ++k) {
      const ProjectorPass& pass = passes[k];
      if (!visible[k]) continue;
      if (pass.retained && !retained_bound) {
        Impl::BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, d.retained_video_array);
        Impl::BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, d.retained_shadows.static_array);
        const GLenum retained_buffers[] = {GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
        glDrawBuffers(2, retained_buffers);
        ApplyPassState(Pass::kProjector, /*blend=*/true);
        retained_bound = true;
      }
      const float scale = pass.retained ? static_cast<float>(std::pow(pass.fade, kNewerWins)) : 1.0f;
      d.DrawProjectorPass(*pass.projector, pass.layer, static_cast<GLint>(36 * k), last_wins && !pass.retained,
                          pass.fade, scale);
    }

    glBindFramebuffer(GL_FRAMEBUFFER, target);
    d.Resolve(view, any_live, any_retained);
    d.DrawLines(view);
  }
  glBindVertexArray(0);
  glUseProgram(0);
  ++d.stats.frames;
  return CheckGl("Render");
}

absl::StatusOr<std::vector<float>> Renderer::ReadLinearDepth(const View& view) const {
  const Impl& d = *impl_;
  const Viewport& v = view.viewport;
  if (d.target_width == 0 || v.x < 0 || v.y < 0 || v.width <= 0 || v.height <= 0 || v.x + v.width > d.target_width ||
      v.y + v.height > d.target_height) {
    return absl::FailedPreconditionError("ReadLinearDepth: the view's viewport is not inside the last Render's framebuffer");
  }
  FramebufferGuard guard;
  std::vector<float> window_depth(static_cast<size_t>(v.width) * v.height);
  std::vector<uint8_t> color(static_cast<size_t>(v.width) * v.height * 4);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, d.fbo_gbuffer);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(v.x, v.y, v.width, v.height, GL_DEPTH_COMPONENT, GL_FLOAT, window_depth.data());
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glReadPixels(v.x, v.y, v.width, v.height, GL_RGBA, GL_UNSIGNED_BYTE, color.data());
  if (absl::Status s = CheckGl("ReadLinearDepth"); !s.ok()) return s;
  const Eigen::Matrix4d eye_from_clip = view.projection.inverse();
  std::vector<float> depth(window_depth.size());
  for (int row = 0; row < v.height; ++row) {
    const int gl_row = v.height - 1 - row;
    for (int col = 0; col < v.width; ++col) {
      const size_t src = static_cast<size_t>(gl_row) * v.width + col;
      float& out = depth[static_cast<size_t>(row) * v.width + col];
      if (color[src * 4 + 3] != 255) {  // nothing or sky
        out = std::numeric_limits<float>::infinity();
        continue;
      }
      const Eigen::Vector4d ndc(2 * (col + 0.5) / v.width - 1, 2 * (gl_row + 0.5) / v.height - 1,
                                2.0 * window_depth[src] - 1, 1);
      const Eigen::Vector4d eye = eye_from_clip * ndc;
      out = static_cast<float>(-eye.z() / eye.w());
    }
  }
  return depth;
}

}  // namespace ave::viewer
