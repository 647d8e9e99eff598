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
constexpr GLint kMappingUnit = 8;
constexpr GLuint kMappingImageUnit = 0;
// Live projectors per combined pass (projector.frag.glsl COMBINED: BATCH); 48 floats of uniforms each.
constexpr int kCombinedBatch = 16;
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

// Stencil of the shadow-tested cached resolve: volume counts (kMark) in the low bits, then a bit
// for pixels with an entry the models may hide (kMarkEntries).
constexpr GLuint kVolumeStencilBits = 0x7F, kEntryStencilBit = 0x80;

enum class Pass {
  kUpload, kShadow, kGbuffer, kProjector, kCombined, kResolve, kMark, kMarkEntries, kResolveMarked, kResolveInVolumes,
  kLines
};

// Every fixed-function state change of the renderer is here (STYLE habit 6).
void ApplyPassState(Pass pass, bool blend = false) {
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_CLAMP);
  glDisable(GL_POLYGON_OFFSET_FILL);
  glDisable(GL_STENCIL_TEST);
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
      glEnable(GL_CULL_FACE);
      glCullFace(GL_FRONT);
      glEnable(GL_DEPTH_CLAMP);
      [[fallthrough]];
    case Pass::kCombined:
      // (kCombined alone: full-screen triangles of the combined live passes, added like projector
      // passes.)
      glEnable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
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
    case Pass::kMark:
      // Counts, in the stencil, the convex volumes (wound counter-clockwise from outside) that
      // hold the surface already in the depth buffer: +1 for a back face behind the surface, -1
      // for a front face behind it, so a volume adds 1 exactly where its entry lies before the
      // surface and its exit after (the eye inside it: no entry). Depth clamping keeps faces
      // beyond the far plane (at depth 1, behind any surface); cleared pixels count nothing.
      glEnable(GL_DEPTH_CLAMP);
      glEnable(GL_SCISSOR_TEST);
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_GREATER);
      glDepthMask(GL_FALSE);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      glEnable(GL_STENCIL_TEST);
      glStencilMask(kVolumeStencilBits);
      glStencilFunc(GL_ALWAYS, 0, 0xFF);
      glStencilOpSeparate(GL_BACK, GL_KEEP, GL_KEEP, GL_INCR_WRAP);
      glStencilOpSeparate(GL_FRONT, GL_KEEP, GL_KEEP, GL_DECR_WRAP);
      break;
    case Pass::kMarkEntries:
      // Where some volume holds the surface, sets kEntryStencilBit where the fragment survives
      // (the resolve's MARK variant discards pixels none of whose entries the models may hide).
      glEnable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      glEnable(GL_STENCIL_TEST);
      glStencilMask(kEntryStencilBit);
      glStencilFunc(GL_NOTEQUAL, kEntryStencilBit, kVolumeStencilBits);
      glStencilOp(GL_KEEP, GL_KEEP, GL_REPLACE);
      break;
    case Pass::kResolveMarked:
    case Pass::kResolveInVolumes:
      // Colour only where kMarkEntries set its bit (or kMark counted a volume): the shader writes no depth and never discards, so the
      // stencil test runs before it and llvmpipe skips blocks that fail it. Without a stencil
      // buffer the test passes everywhere: the same picture, at full cost.
      glEnable(GL_SCISSOR_TEST);
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
      glEnable(GL_STENCIL_TEST);
      glStencilMask(0);
      if (pass == Pass::kResolveMarked) {
        glStencilFunc(GL_EQUAL, kEntryStencilBit, kEntryStencilBit);
      } else {
        glStencilFunc(GL_NOTEQUAL, 0, kVolumeStencilBits);
      }
      glStencilOp(GL_KEEP, GL_KEEP, GL_KEEP);
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
// The corners of the image rectangle `ndc` (x0, y0, x1, y1) at depth_m along the optical axis.
std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              const Eigen::Vector4d& ndc_rect, double depth_m) {
  std::array<Eigen::Vector3d, 4> corners;
  const double ndc[4][2] = {{ndc_rect[0], ndc_rect[1]}, {ndc_rect[2], ndc_rect[1]}, {ndc_rect[2], ndc_rect[3]},
                            {ndc_rect[0], ndc_rect[3]}};
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector4d e = eye_from_clip * Eigen::Vector4d(ndc[k][0], ndc[k][1], -1, 1);
    e /= e.w();
    const Eigen::Vector3d at_depth = e.head<3>() * (depth_m / -e.z());
    corners[k] = (local_from_eye * at_depth.homogeneous()).head<3>();
  }
  return corners;
}

// The image (NDC scaled by `scale`) at depth_m.
std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              double scale, double depth_m) {
  return FrustumCorners(local_from_eye, eye_from_clip, Eigen::Vector4d(-scale, -scale, scale, scale), depth_m);
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

// How far (pixels of a layer_width x layer_height image) the image centre and corners at depth_m
// in front of `from` move when seen through `to` instead: 0 for the same pose.
double ReprojectionShiftPx(const Projector& from, const Projector& to, double depth_m, int layer_width,
                           int layer_height) {
  const Eigen::Matrix4d local_from_eye = from.view.inverse(), eye_from_clip = from.projection.inverse();
  std::array<Eigen::Vector3d, 5> points;
  const std::array<Eigen::Vector3d, 4> corners = FrustumCorners(local_from_eye, eye_from_clip, 1, depth_m);
  std::copy(corners.begin(), corners.end(), points.begin());
  points[4] = (local_from_eye * Eigen::Vector4d(0, 0, -depth_m, 1)).head<3>();
  double shift = 0;
  for (const Eigen::Vector3d& x : points) {
    const Eigen::Vector4d a = from.projection * from.view * x.homogeneous(), b = to.projection * to.view * x.homogeneous();
    if (!(b.w() > 1e-9)) return std::numeric_limits<double>::infinity();
    const Eigen::Vector2d d = a.head<2>() / a.w() - b.head<2>() / b.w();
    shift = std::max(shift, Eigen::Vector2d(0.5 * layer_width * d.x(), 0.5 * layer_height * d.y()).norm());
  }
  return shift;
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
  bool dynamic_has_models = false;  // the dynamic layer holds some model (else it equals the static one)
  Viewport dynamic_rect;            // where (shadow-map pixels) it may differ from the static layer
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
// The shadow-map rectangle `rect` (pixels) where a projector's dynamic layer may differ from its
// static one, as (x0, y0, x1, y1) in the projector's own undistorted NDC, padded for the normal
// offset and the 2x2 comparison filter of the lookups.
Eigen::Vector4d ModelNdcRect(const Projector& p, const Viewport& rect, int shadow_map_size) {
  const double pad = kNormalOffsetTexels + 2, margin = DistortionMargin(p);
  return margin * Eigen::Vector4d(2 * (rect.x - pad) / shadow_map_size - 1, 2 * (rect.y - pad) / shadow_map_size - 1,
                                  2 * (rect.x + rect.width + pad) / shadow_map_size - 1,
                                  2 * (rect.y + rect.height + pad) / shadow_map_size - 1);
}

// Where a projector's (distorted) image, as video (u, v) of its layer, may show the dynamic models
// its shadow map holds in `rect` (ModelNdcRect): an entry whose (u, v) lies outside sees the static
// shadow map only. The distortion is bounded over a grid of the rectangle (the forward model
// evaluated as the projector shader does).
Eigen::Vector4f ModelUvRect(const Projector& p, const Viewport& rect, int shadow_map_size, int layer_width,
                            int layer_height) {
  const Eigen::Vector4d r = ModelNdcRect(p, rect, shadow_map_size);
  const double x0 = r[0], y0 = r[1], x1 = r[2], y1 = r[3];
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  const bool distorted = HasDistortion(p);
  const int steps = distorted ? 16 : 1;
  const double p00 = p.projection(0, 0), p02 = p.projection(0, 2), p11 = p.projection(1, 1), p12 = p.projection(1, 2);
  const std::array<double, 5>& k = p.distortion;
  for (int i = 0; i <= steps; ++i) {
    for (int j = 0; j <= steps; ++j) {
      Eigen::Vector2d ndc(x0 + (x1 - x0) * i / steps, y0 + (y1 - y0) * j / steps);
      if (distorted) {
        const double x = (ndc.x() + p02) / p00, y = -(ndc.y() + p12) / p11, r2 = x * x + y * y;
        const double radial = 1 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]));
        const double xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
        const double yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
        ndc = Eigen::Vector2d(p00 * xd - p02, -p11 * yd - p12);
      }
      lo = lo.cwiseMin(ndc);
      hi = hi.cwiseMax(ndc);
    }
  }
  // One grid cell of slack for the curvature between samples, and a video texel.
  const Eigen::Vector2d slack = distorted ? Eigen::Vector2d((hi - lo) / steps) : Eigen::Vector2d::Zero();
  lo -= slack;
  hi += slack;
  const float du = 1.0f / static_cast<float>(layer_width), dv = 1.0f / static_cast<float>(layer_height);
  return Eigen::Vector4f(static_cast<float>(0.5 + 0.5 * lo.x()) - du, static_cast<float>(0.5 - 0.5 * hi.y()) - dv,
                         static_cast<float>(0.5 + 0.5 * hi.x()) + du, static_cast<float>(0.5 - 0.5 * lo.y()) + dv);
}

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

// A frustum piece between the rectangles near_c and far_c (corners in the same order): 12
// triangles wound counter-clockwise from outside.
void AppendFrustumPiece(const std::array<Eigen::Vector3d, 4>& near_c, const std::array<Eigen::Vector3d, 4>& far_c,
                        std::vector<LineVertex>& out) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) centre += near_c[k] + far_c[k];
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

// Where a projector's volume ends (depth along its axis): at the farthest scene point, or nearer
// where its static shadow map saw no farther surface.
double VolumeFarM(const Projector& p, const Bounds& scene, const ShadowSlot& shadow) {
  double far_m = p.far_m;
  if (!scene.empty()) {
    double farthest = 0;
    for (const Eigen::Vector3d& c : scene.Corners()) farthest = std::max(farthest, -(p.view * c.homogeneous()).z());
    far_m = std::clamp(farthest * 1.01, p.near_m * 1.01, p.far_m);
  }
  // The static shadow map says how far the projector actually sees (dynamic models stand on the
  // static model, within that depth). Most cameras look at the ground: a much smaller footprint.
  if (shadow.valid && !shadow.sees_void) far_m = std::clamp(shadow.visible_far_m * 1.02 + 1, p.near_m * 1.01, far_m);
  return far_m;
}

// The frustum volume of a projector, cut at VolumeFarM (fewer pixels to shade) and widened by the
// distortion margin: 12 triangles wound counter-clockwise from outside.
void AppendFrustumVolume(const Projector& p, const Bounds& scene, const ShadowSlot& shadow, std::vector<LineVertex>& out,
                         std::array<Eigen::Vector3d, 8>& corners_out) {
  const Eigen::Matrix4d local_from_eye = p.view.inverse();
  const Eigen::Matrix4d eye_from_clip = p.projection.inverse();
  const double margin = DistortionMargin(p);
  const std::array<Eigen::Vector3d, 4> near_c = FrustumCorners(local_from_eye, eye_from_clip, margin, p.near_m);
  const std::array<Eigen::Vector3d, 4> far_c =
      FrustumCorners(local_from_eye, eye_from_clip, margin, VolumeFarM(p, scene, shadow));
  for (int k = 0; k < 4; ++k) {
    corners_out[k] = near_c[k];
    corners_out[k + 4] = far_c[k];
  }
  AppendFrustumPiece(near_c, far_c, out);
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

// A program with its uniform locations.
struct Program {
  GLuint id = 0;
  Uniforms u;
};

// One projector pass of a frame: a live layer or a retained snapshot, with its frustum volume's
// corners (36 volume vertices each, in pass order).
struct ProjectorPass {
  const Projector* projector;
  int layer;
  bool retained;
  float fade;
  std::array<Eigen::Vector3d, 8> corners;
};

// A screen rectangle in framebuffer pixels (GL convention, like Viewport).
bool Overlap(const Viewport& a, const Viewport& b) {
  return a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height;
}

Viewport Union(const Viewport& a, const Viewport& b) {
  const int x0 = std::min(a.x, b.x), y0 = std::min(a.y, b.y);
  const int x1 = std::max(a.x + a.width, b.x + b.width), y1 = std::max(a.y + a.height, b.y + b.height);
  return Viewport{x0, y0, x1 - x0, y1 - y0};
}

Viewport Intersection(const Viewport& a, const Viewport& b) {
  const int x0 = std::max(a.x, b.x), y0 = std::max(a.y, b.y);
  const int x1 = std::min(a.x + a.width, b.x + b.width), y1 = std::min(a.y + a.height, b.y + b.height);
  return Viewport{x0, y0, std::max(0, x1 - x0), std::max(0, y1 - y0)};
}

// The pixels of `viewport` that the convex hull of the points may cover in a view with this
// matrix, padded by two pixels. Points are homogeneous: w = 0 is a direction, standing for the
// whole ray towards it from the other points (its image ends at the direction's vanishing point).
// The whole viewport when a point or direction lies behind the eye (it cannot be bounded there).
std::optional<Viewport> ScreenRect(const std::vector<Eigen::Vector4d>& points, const Eigen::Matrix4d& clip_from_local,
                                   const Viewport& viewport) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Eigen::Vector4d& p : points) {
    const Eigen::Vector4d clip = clip_from_local * p;
    if (!(clip.w() > 1e-6)) return viewport;
    const Eigen::Vector2d ndc = clip.head<2>() / clip.w();
    lo = lo.cwiseMin(ndc);
    hi = hi.cwiseMax(ndc);
  }
  constexpr double kPadPixels = 2;
  const double x0 = viewport.x + (0.5 * lo.x() + 0.5) * viewport.width - kPadPixels;
  const double x1 = viewport.x + (0.5 * hi.x() + 0.5) * viewport.width + kPadPixels;
  const double y0 = viewport.y + (0.5 * lo.y() + 0.5) * viewport.height - kPadPixels;
  const double y1 = viewport.y + (0.5 * hi.y() + 0.5) * viewport.height + kPadPixels;
  const int ix0 = static_cast<int>(std::max<double>(viewport.x, std::floor(x0)));
  const int iy0 = static_cast<int>(std::max<double>(viewport.y, std::floor(y0)));
  const int ix1 = static_cast<int>(std::min<double>(viewport.x + viewport.width, std::ceil(x1)));
  const int iy1 = static_cast<int>(std::min<double>(viewport.y + viewport.height, std::ceil(y1)));
  if (ix1 <= ix0 || iy1 <= iy0) return std::nullopt;
  return Viewport{ix0, iy0, ix1 - ix0, iy1 - iy0};
}

// The parts of a projector's frustum where its dynamic shadow map may differ from the static one:
// per model in its view, the rectangle of the shadow map the model covers (ModelNdcRect), from the
// model's nearest corner to the end of the projector's volume. A surface point outside them sees
// the projector past no model. 36 vertices per model.
void AppendShadowVolumes(const Projector& p, const ShadowSlot& slot, const std::vector<Bounds>& models,
                         const Bounds& scene, int shadow_map_size, std::vector<LineVertex>& out) {
  if (!slot.dynamic_has_models) return;
  const Eigen::Matrix4d shadow_clip = MakeProjectorGl(p, shadow_map_size).shadow_projection * p.view;
  const Eigen::Matrix4d local_from_eye = p.view.inverse(), eye_from_clip = p.projection.inverse();
  const double far_m = VolumeFarM(p, scene, slot);
  const Viewport map{0, 0, shadow_map_size, shadow_map_size};
  for (const Bounds& b : models) {
    const std::array<Eigen::Vector3d, 8> corners = b.Corners();
    if (!VolumeMayBeVisible(corners, shadow_clip)) continue;
    std::vector<Eigen::Vector4d> points;
    double nearest = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& c : corners) {
      points.push_back(c.homogeneous());
      nearest = std::min(nearest, -(p.view * c.homogeneous()).z());
    }
    const std::optional<Viewport> rect = ScreenRect(points, shadow_clip, map);
    if (!rect) continue;
    const Eigen::Vector4d ndc = ModelNdcRect(p, *rect, shadow_map_size);
    const double near_m = std::clamp(nearest, p.near_m, far_m);
    AppendFrustumPiece(FrustumCorners(local_from_eye, eye_from_clip, ndc, near_m),
                       FrustumCorners(local_from_eye, eye_from_clip, ndc, far_m), out);
  }
}

// What a view's cached G-buffer and mapping were built from (exact comparison: any change rebuilds).
struct ViewCache {
  bool valid = false;
  Viewport viewport;
  std::vector<double> signature;
  std::vector<double> last_signature;  // of the view's previous frame, cached or not
  // The static G-buffer in the cache textures (under `viewport`) was drawn for these view inputs
  // (StaticSignature): still usable when only projectors changed and the mapping is not.
  std::vector<double> static_signature;
  bool static_valid = false;
  double built_s = 0;  // Now() when the retained targets were drawn
  bool any_live = false, any_retained = false;
  std::vector<Viewport> patches;  // rectangles drawn exactly in the last frame (working G-buffer)
  uint64_t last_frame = 0;        // RenderStats::frames after the Render that last drew the view
};

void AppendMatrix(const Eigen::Matrix4d& m, std::vector<double>& out) { out.insert(out.end(), m.data(), m.data() + 16); }

}  // namespace

struct Renderer::Impl {
  RendererOptions options;
  GLuint gbuffer_program = 0, shadow_program = 0, line_program = 0;
  // Projector passes: colour accumulation, and the view cache's mapping build (MAPPING); the live
  // projectors of a view in batches of kCombinedBatch full-screen passes (COMBINED).
  Program projector, mapping, combined;
  // Resolve variants, index any_live + 2 * any_retained + 4 * cached + 8 * shadowed
  // (resolve.frag.glsl: LIVE, RETAINED, CACHED, SHADOWED; shadowed only with cached and live).
  std::array<Program, 32> resolve;  // by variant bits: live 1, retained 2, cached 4, shadowed 8, mark 16
  Uniforms gbuffer_u;
  GLint shadow_clip_from_local = -1, line_clip_from_local = -1;

  MeshBuffers static_mesh, dynamic_mesh, sky_mesh, lines, volumes;
  // In `volumes` after the frustum volumes: the live projectors' shadow volumes of this frame.
  GLint shadow_volume_first = 0;
  GLsizei shadow_volume_count = 0;
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
  // View cache (RendererOptions::view_cache), framebuffer-sized and shared by views that do not
  // overlap: the static G-buffer, retained accumulation, and view_cache_entries mapping layers.
  bool cache_supported = false;  // GL 4.3+
  GLuint fbo_cache_gbuffer = 0, fbo_cache_accum = 0, fbo_mapping = 0;
  GLuint cache_color = 0, cache_normal = 0, cache_depth = 0, cache_retained = 0, cache_fade = 0, mapping_array = 0;
  std::vector<ViewCache> view_caches;  // by the view's index in Render's views
  std::vector<Bounds> model_bounds;    // per dynamic model
  // Views of the last Render drawn at reduced resolution: (viewport, the part of it drawn into).
  std::vector<std::pair<Viewport, Viewport>> reduced_views;

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
    const GLuint cache_textures[] = {cache_color, cache_normal, cache_depth, cache_retained, cache_fade, mapping_array};
    glDeleteTextures(6, cache_textures);
    const GLuint cache_fbos[] = {fbo_cache_gbuffer, fbo_cache_accum, fbo_mapping};
    glDeleteFramebuffers(3, cache_fbos);
    glDeleteVertexArrays(1, &empty_vao);
    live_shadows.Destroy();
    retained_shadows.Destroy();
    const GLuint textures[] = {video_array,   retained_video_array, scratch_texture, gbuffer_color, gbuffer_normal,
                               gbuffer_depth, accum_live,           accum_retained,  accum_fade};
    glDeleteTextures(9, textures);
    const GLuint fbos[] = {fbo_video_src, fbo_video_dst, fbo_shadow_src, fbo_shadow_dst, fbo_gbuffer, fbo_accum};
    glDeleteFramebuffers(6, fbos);
    for (GLuint program : {gbuffer_program, shadow_program, line_program, projector.id, mapping.id, combined.id}) {
      if (program) glDeleteProgram(program);
    }
    for (const Program& program : resolve) {
      if (program.id) glDeleteProgram(program.id);
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
    if (absl::Status s = MakeGBuffer(fbo_gbuffer, width, height, "G-buffer", gbuffer_color, gbuffer_normal, gbuffer_depth);
        !s.ok()) {
      return s;
    }
    accum_live = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
    accum_retained = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
    accum_fade = MakeTexture2D(GL_R32F, GL_RED, GL_FLOAT, width, height);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_accum);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, accum_live, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, accum_retained, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT2, GL_TEXTURE_2D, accum_fade, 0);
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "projector accumulation"); !s.ok()) return s;
    target_width = width;
    target_height = height;
    if (absl::Status s = EnsureCacheTargets(width, height); !s.ok()) return s;
    return CheckGl("render targets");
  }

  bool CacheOn() const { return options.view_cache && cache_supported; }

  // A G-buffer (shaded colour, packed normal, depth) of width x height attached to `fbo`.
  static absl::Status MakeGBuffer(GLuint fbo, int width, int height, const char* what, GLuint& color, GLuint& normal,
                                  GLuint& depth) {
    color = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
    normal = MakeTexture2D(GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE, width, height);
    depth = MakeTexture2D(GL_DEPTH_COMPONENT32F, GL_DEPTH_COMPONENT, GL_FLOAT, width, height);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, color, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, normal, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, depth, 0);
    const GLenum gbuffers[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(2, gbuffers);
    return CheckFramebuffer(GL_FRAMEBUFFER, what);
  }

  absl::Status EnsureCacheTargets(int width, int height) {
    view_caches.clear();
    const GLuint old[] = {cache_color, cache_normal, cache_depth, cache_retained, cache_fade, mapping_array};
    glDeleteTextures(6, old);
    cache_color = cache_normal = cache_depth = cache_retained = cache_fade = mapping_array = 0;
    if (!CacheOn()) return absl::OkStatus();
    if (absl::Status s =
            MakeGBuffer(fbo_cache_gbuffer, width, height, "view cache G-buffer", cache_color, cache_normal, cache_depth);
        !s.ok()) {
      return s;
    }
    cache_retained = MakeTexture2D(GL_RGBA32F, GL_RGBA, GL_FLOAT, width, height);
    cache_fade = MakeTexture2D(GL_R32F, GL_RED, GL_FLOAT, width, height);
    glGenTextures(1, &mapping_array);
    glBindTexture(GL_TEXTURE_2D_ARRAY, mapping_array);
    glTexStorage3D(GL_TEXTURE_2D_ARRAY, 1, GL_RGBA32F, width, height, options.view_cache_entries);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_cache_accum);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT1, GL_TEXTURE_2D, cache_retained, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT2, GL_TEXTURE_2D, cache_fade, 0);
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "view cache retained"); !s.ok()) return s;
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_mapping);
    std::array<GLenum, kMaxViewCacheEntries> entries{};
    for (int k = 0; k < options.view_cache_entries; ++k) {
      glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0 + k, mapping_array, 0, k);
      entries[k] = GL_COLOR_ATTACHMENT0 + k;
    }
    glDrawBuffers(options.view_cache_entries, entries.data());
    if (absl::Status s = CheckFramebuffer(GL_FRAMEBUFFER, "view cache mapping"); !s.ok()) return s;
    return CheckGl("view cache targets");
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
    const Eigen::Matrix4d shadow_clip = Eigen::Map<const Eigen::Matrix4f>(clip_from_local.data()).cast<double>();
    const bool models_inside = with_dynamic && std::any_of(model_bounds.begin(), model_bounds.end(), [&](const Bounds& b) {
                                 return VolumeMayBeVisible(b.Corners(), shadow_clip);
                               });
    if (!static_dirty && !slot.dynamic_has_models && !models_inside) {
      // No model was or is in this projector's view: its dynamic layer is still the static one.
      slot.dynamic_version = dynamic_version;
      return absl::OkStatus();
    }
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
      DrawStaticChunks(shadow_clip);
      ++counter;
      ReadShadowExtent(shadow_projection, slot);
    }
    if (dynamic_dirty) {
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_shadow_dst);
      glFramebufferTextureLayer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, arrays.dynamic_array, 0, layer);
      if (absl::Status s = CheckFramebuffer(GL_DRAW_FRAMEBUFFER, "dynamic shadow map"); !s.ok()) return s;
      // Only where the models were or are does the dynamic layer differ from the static one: the
      // copy (a full-size blit costs llvmpipe a 1024^2 depth pass per projector) is limited to that.
      const Viewport full{0, 0, size, size};
      std::optional<Viewport> now;
      if (models_inside) {
        std::vector<Eigen::Vector4d> points;
        for (const Bounds& b : model_bounds) {
          for (const Eigen::Vector3d& c : b.Corners()) points.push_back(c.homogeneous());
        }
        now = ScreenRect(points, shadow_clip, full);
      }
      std::optional<Viewport> copy = static_dirty ? std::optional<Viewport>(full) : now;
      if (!static_dirty && slot.dynamic_has_models) copy = copy ? Union(*copy, slot.dynamic_rect) : slot.dynamic_rect;
      if (copy) {
        const Viewport& r = *copy;
        glBlitFramebuffer(r.x, r.y, r.x + r.width, r.y + r.height, r.x, r.y, r.x + r.width, r.y + r.height,
                          GL_DEPTH_BUFFER_BIT, GL_NEAREST);
      }
      dynamic_mesh.Draw(GL_TRIANGLES);
      ++stats.dynamic_shadow_updates;
      slot.dynamic_has_models = now.has_value();
      slot.dynamic_rect = now.value_or(Viewport{});
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

  // The static model and sky (with_static) and the dynamic models (with_dynamic) into the bound
  // G-buffer.
  void DrawGbuffer(const View& view, bool with_static, bool with_dynamic) {
    ApplyPassState(Pass::kGbuffer);
    glUseProgram(gbuffer_program);
    const Uniforms& u = gbuffer_u;
    glUniformMatrix4fv(u["u_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    const Eigen::Vector3f sun = options.sun_direction.normalized();
    glUniform3f(u["u_sun_direction"], sun.x(), sun.y(), sun.z());
    glUniform1f(u["u_ambient"], options.ambient);
    glUniform1f(u["u_diffuse"], options.diffuse);
    glUniform3f(u["u_sky_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
    if (with_static) DrawStaticChunks(view.projection * view.view);
    glEnable(GL_CULL_FACE);
    glCullFace(GL_BACK);
    if (with_dynamic) dynamic_mesh.Draw(GL_TRIANGLES);
    if (with_static && options.display.sky) sky_mesh.Draw(GL_TRIANGLES);
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

  // A local point (homogeneous) from (window x, y in framebuffer pixels, NDC z, 1) of the view.
  static Eigen::Matrix4d LocalFromWindow(const View& view) {
    const Viewport& v = view.viewport;
    Eigen::Matrix4d ndc_from_window = Eigen::Matrix4d::Identity();
    ndc_from_window(0, 0) = 2.0 / v.width;
    ndc_from_window(0, 3) = -1 - 2.0 * v.x / v.width;
    ndc_from_window(1, 1) = 2.0 / v.height;
    ndc_from_window(1, 3) = -1 - 2.0 * v.y / v.height;
    return (view.projection * view.view).inverse() * ndc_from_window;
  }

  // `program` reads the G-buffer textures `normal` and `depth` (the working or the cached one).
  void BindProjectorInputs(const View& view, const Program& program, GLuint normal, GLuint depth) {
    glUseProgram(program.id);
    const Uniforms& u = program.u;
    glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
    glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
    glUniform1i(u["u_video"], kVideoUnit);
    glUniform1i(u["u_shadow"], kShadowUnit);
    glUniformMatrix4fv(u["u_view_clip_from_local"], 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(LocalFromWindow(view)).data());
    const DisplayOptions& display = options.display;
    glUniform1f(u["u_feather"], static_cast<float>(display.seam_feather));
    glUniform1i(u["u_best_view"], display.overlap == OverlapPolicy::kBestView ? 1 : 0);
    BindTexture(kGbufferNormalUnit, GL_TEXTURE_2D, normal);
    BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, depth);
  }

  static void BindTexture(GLint unit, GLenum target, GLuint texture) {
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(target, texture);
    glActiveTexture(GL_TEXTURE0);
  }

  void DrawProjectorPass(const Uniforms& u, const Projector& p, int layer, GLint first_vertex, bool last_wins,
                         float fade, float weight_scale) {
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

  // cache: resolve from a view cache (its G-buffer, retained targets and mapping), else from the
  // working G-buffer and accumulation targets.
  // shadowed (with a cache and live passes): cached entries are tested against the shadow maps
  // with the dynamic models (the layers' matrices come from `passes`).
  // drawn (uncached): the viewport the working targets hold the view in (the view's own, or a
  // reduced one at the same corner: scaled up).
  // shadowed_pass (with shadowed): kMarkEntries only sets kEntryStencilBit where some entry may be
  // hidden; kResolveMarked draws where that bit is set, kResolveInVolumes where the volume count
  // is not 0 (MarkShadowVolumes).
  void Resolve(const View& view, bool any_live, bool any_retained, const ViewCache* cache = nullptr,
               const std::vector<ProjectorPass>* shadowed = nullptr, const Viewport* drawn = nullptr,
               Pass shadowed_pass = Pass::kResolveMarked) {
    const bool mark = shadowed && shadowed_pass == Pass::kMarkEntries;
    ApplyPassState(shadowed ? shadowed_pass : Pass::kResolve);
    const int variant =
        (any_live ? 1 : 0) + (any_retained ? 2 : 0) + (cache ? 4 : 0) + (shadowed ? 8 : 0) + (mark ? 16 : 0);
    glUseProgram(resolve[variant].id);
    const Uniforms& u = resolve[variant].u;
    const Viewport& v = view.viewport;
    glUniform2f(u["u_source_origin"], static_cast<float>(v.x), static_cast<float>(v.y));
    glUniform2f(u["u_source_scale"], drawn ? static_cast<float>(drawn->width) / v.width : 1.0f,
                drawn ? static_cast<float>(drawn->height) / v.height : 1.0f);
    glUniform1i(u["u_gbuffer_color"], kGbufferColorUnit);
    glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
    glUniform1i(u["u_live"], kLiveUnit);
    glUniform1i(u["u_retained"], kRetainedUnit);
    glUniform1i(u["u_fade"], kFadeUnit);
    glUniform3f(u["u_clear_color"], view.clear_color.x(), view.clear_color.y(), view.clear_color.z());
    glUniform1i(u["u_tint_by_age"], options.display.tint_by_age ? 1 : 0);
    const double half_life = options.display.retention_half_life_s;
    const double elapsed = cache ? std::max(0.0, Now() - cache->built_s) : 0.0;
    glUniform1f(u["u_fade_scale"], half_life > 0 ? static_cast<float>(std::pow(0.5, elapsed / half_life)) : 0.0f);
    BindTexture(kGbufferColorUnit, GL_TEXTURE_2D, cache ? cache_color : gbuffer_color);
    BindTexture(kGbufferDepthUnit, GL_TEXTURE_2D, cache ? cache_depth : gbuffer_depth);
    BindTexture(kRetainedUnit, GL_TEXTURE_2D, cache ? cache_retained : accum_retained);
    BindTexture(kFadeUnit, GL_TEXTURE_2D, cache ? cache_fade : accum_fade);
    if (cache) {
      glUniform1i(u["u_mapping"], kMappingUnit);
      glUniform1i(u["u_video"], kVideoUnit);
      glUniform1i(u["u_last_wins"], options.display.overlap == OverlapPolicy::kLastWins ? 1 : 0);
      BindTexture(kMappingUnit, GL_TEXTURE_2D_ARRAY, mapping_array);
      BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, video_array);
    } else {
      BindTexture(kLiveUnit, GL_TEXTURE_2D, accum_live);
    }
    if (shadowed) {
      std::vector<float> matrices(16 * kMaxProjectors, 0.0f), position_offset(4 * kMaxProjectors, 0.0f),
          model_uv(4 * kMaxProjectors, 0.0f);
      for (int l = 0; l < kMaxProjectors; ++l) model_uv[4 * l] = 1.0f;  // empty: u0 > u1
      for (const ProjectorPass& pass : *shadowed) {
        if (pass.retained) continue;
        const ShadowSlot& slot = slots[pass.layer].shadow;
        if (!slot.dynamic_has_models) continue;
        const ProjectorGl g = MakeProjectorGl(*pass.projector, options.shadow_map_size);
        std::copy(g.shadow_clip_from_local.begin(), g.shadow_clip_from_local.end(), matrices.begin() + 16 * pass.layer);
        for (int k = 0; k < 3; ++k) position_offset[4 * pass.layer + k] = static_cast<float>(pass.projector->position[k]);
        position_offset[4 * pass.layer + 3] = g.normal_offset;
        const Eigen::Vector4f uv = ModelUvRect(*pass.projector, slot.dynamic_rect, options.shadow_map_size,
                                               options.video_layer_width, options.video_layer_height);
        std::copy(uv.data(), uv.data() + 4, model_uv.begin() + 4 * pass.layer);
      }
      glUniformMatrix4fv(u["u_shadow_clip_from_local"], kMaxProjectors, GL_FALSE, matrices.data());
      glUniform4fv(u["u_position_offset"], kMaxProjectors, position_offset.data());
      glUniform4fv(u["u_model_uv"], kMaxProjectors, model_uv.data());
      glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(LocalFromWindow(view)).data());
      glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
      glUniform1i(u["u_shadow"], kShadowUnit);
      BindTexture(kGbufferNormalUnit, GL_TEXTURE_2D, cache_normal);
      BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, live_shadows.dynamic_array);
    }
    glBindVertexArray(empty_vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
  }

  // The projector passes of one view into the working accumulation targets, then its resolve
  // into `target`, within the current scissor box. The working G-buffer must hold the view.
  // `output`: the view as it is shown when `view` is a reduced copy of it (moving_view_scale).
  void AccumulateAndResolve(const View& view, const std::vector<ProjectorPass>& passes, const std::vector<char>& visible,
                            bool any_live, bool any_retained, GLuint target, const View* output = nullptr) {
    const bool last_wins = options.display.overlap == OverlapPolicy::kLastWins;
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_accum);
    // Only the targets this view's passes write are cleared, and only those the resolve reads.
    const GLenum none = GL_NONE;
    const GLenum all_accum[] = {any_live ? GLenum{GL_COLOR_ATTACHMENT0} : none,
                                any_retained ? GLenum{GL_COLOR_ATTACHMENT1} : none,
                                any_retained ? GLenum{GL_COLOR_ATTACHMENT2} : none};
    glDrawBuffers(3, all_accum);
    ApplyPassState(Pass::kGbuffer);
    if (any_live || any_retained) glClear(GL_COLOR_BUFFER_BIT);
    BindProjectorInputs(view, projector, gbuffer_normal, gbuffer_depth);
    BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, video_array);
    BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY,
                options.dynamic_objects_cast_shadows ? live_shadows.dynamic_array : live_shadows.static_array);
    const GLenum live_buffers[] = {GL_COLOR_ATTACHMENT0, GL_NONE};
    glDrawBuffers(2, live_buffers);
    ApplyPassState(Pass::kProjector, /*blend=*/!last_wins);
    if (options.combined_live_passes) {
      DrawCombinedLivePasses(view, passes, visible, last_wins);
    } else {
      for (size_t k = 0; k < passes.size(); ++k) {
        if (visible[k] && !passes[k].retained) DrawPass(projector.u, passes[k], k, last_wins);
      }
    }
    if (any_retained) {
      BindProjectorInputs(view, projector, gbuffer_normal, gbuffer_depth);
      DrawRetainedPasses(passes, visible);
    }
    glBindFramebuffer(GL_FRAMEBUFFER, target);
    if (output) {
      const Viewport& o = output->viewport;
      glViewport(o.x, o.y, o.width, o.height);
      glScissor(o.x, o.y, o.width, o.height);
      Resolve(*output, any_live, any_retained, nullptr, nullptr, &view.viewport);
    } else {
      Resolve(view, any_live, any_retained);
    }
  }

  // The view's visible live passes whose footprint meets the current scissor box, kCombinedBatch at
  // a time in one full-screen pass each (scissored to the batch's footprints), into the bound
  // accumulation target (draw buffer 0, blend state set): the G-buffer is read and the point
  // reconstructed once per pixel and batch instead of once per projector.
  void DrawCombinedLivePasses(const View& view, const std::vector<ProjectorPass>& passes,
                              const std::vector<char>& visible, bool last_wins) {
    GLint box[4];
    glGetIntegerv(GL_SCISSOR_BOX, box);
    const Viewport scissor{box[0], box[1], box[2], box[3]};
    const Eigen::Matrix4d clip_from_local = view.projection * view.view;
    std::vector<std::pair<const ProjectorPass*, Viewport>> reach;
    for (size_t k = 0; k < passes.size(); ++k) {
      if (!visible[k] || passes[k].retained) continue;
      std::vector<Eigen::Vector4d> corners;
      for (const Eigen::Vector3d& c : passes[k].corners) corners.push_back(c.homogeneous());
      const std::optional<Viewport> rect = ScreenRect(corners, clip_from_local, view.viewport);
      if (rect && Overlap(*rect, scissor)) reach.emplace_back(&passes[k], Intersection(*rect, scissor));
    }
    if (reach.empty()) return;
    ApplyPassState(Pass::kCombined, /*blend=*/!last_wins);
    glUseProgram(combined.id);
    const Uniforms& u = combined.u;
    glUniform1i(u["u_gbuffer_normal"], kGbufferNormalUnit);
    glUniform1i(u["u_gbuffer_depth"], kGbufferDepthUnit);
    glUniform1i(u["u_video"], kVideoUnit);
    glUniform1i(u["u_shadow"], kShadowUnit);
    glUniformMatrix4fv(u["u_local_from_window"], 1, GL_FALSE, ToGlArray(LocalFromWindow(view)).data());
    glUniform1f(u["u_feather"], static_cast<float>(options.display.seam_feather));
    glUniform1i(u["u_best_view"], options.display.overlap == OverlapPolicy::kBestView ? 1 : 0);
    glUniform1i(u["u_last_wins"], last_wins ? 1 : 0);
    glUniform1f(u["u_weight_scale"], 1.0f);
    glBindVertexArray(empty_vao);
    for (size_t first = 0; first < reach.size(); first += kCombinedBatch) {
      const size_t count = std::min<size_t>(kCombinedBatch, reach.size() - first);
      std::vector<float> clips(16 * count), shadow_clips(16 * count), pinholes(4 * count), distortions(4 * count),
          position_layers(4 * count), extras(4 * count);
      Viewport area = reach[first].second;
      for (size_t k = 0; k < count; ++k) {
        const auto& [pass, rect] = reach[first + k];
        area = Union(area, rect);
        const Projector& p = *pass->projector;
        const ProjectorGl g = MakeProjectorGl(p, options.shadow_map_size);
        std::copy(g.clip_from_local.begin(), g.clip_from_local.end(), clips.begin() + 16 * k);
        std::copy(g.shadow_clip_from_local.begin(), g.shadow_clip_from_local.end(), shadow_clips.begin() + 16 * k);
        std::copy(g.pinhole, g.pinhole + 4, pinholes.begin() + 4 * k);
        std::copy(g.distortion, g.distortion + 4, distortions.begin() + 4 * k);
        for (int i = 0; i < 3; ++i) position_layers[4 * k + i] = static_cast<float>(p.position[i]);
        position_layers[4 * k + 3] = static_cast<float>(pass->layer);
        const float e[4] = {static_cast<float>(1 / DistortionMargin(p)), g.distortion[4], g.distorted ? 1.0f : 0.0f,
                            g.normal_offset};
        std::copy(e, e + 4, extras.begin() + 4 * k);
      }
      const GLsizei n = static_cast<GLsizei>(count);
      glUniform1i(u["u_count"], n);
      glUniformMatrix4fv(u["u_clips"], n, GL_FALSE, clips.data());
      glUniformMatrix4fv(u["u_shadow_clips"], n, GL_FALSE, shadow_clips.data());
      glUniform4fv(u["u_pinholes"], n, pinholes.data());
      glUniform4fv(u["u_distortions"], n, distortions.data());
      glUniform4fv(u["u_position_layers"], n, position_layers.data());
      glUniform4fv(u["u_extras"], n, extras.data());
      glScissor(area.x, area.y, area.width, area.height);
      glDrawArrays(GL_TRIANGLES, 0, 3);
      stats.projector_passes += count;
    }
    glScissor(scissor.x, scissor.y, scissor.width, scissor.height);
  }

  void DrawPass(const Uniforms& u, const ProjectorPass& pass, size_t index, bool last_wins) {
    const float scale = pass.retained ? static_cast<float>(std::pow(pass.fade, kNewerWins)) : 1.0f;
    DrawProjectorPass(u, *pass.projector, pass.layer, static_cast<GLint>(36 * index), last_wins && !pass.retained,
                      pass.fade, scale);
  }

  // Retained passes into draw buffers 1 and 2 of the bound accumulation framebuffer, whose
  // projector inputs are bound.
  void DrawRetainedPasses(const std::vector<ProjectorPass>& passes, const std::vector<char>& visible) {
    BindTexture(kVideoUnit, GL_TEXTURE_2D_ARRAY, retained_video_array);
    BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, retained_shadows.static_array);
    const GLenum retained_buffers[] = {GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
    glDrawBuffers(2, retained_buffers);
    ApplyPassState(Pass::kProjector, /*blend=*/true);
    for (size_t k = 0; k < passes.size(); ++k) {
      if (visible[k] && passes[k].retained) DrawPass(projector.u, passes[k], k, false);
    }
  }

  // Everything a view's cached G-buffer, mapping and retained targets depend on. Video content is
  // not in it (the mapping is sampled against the current frames), nor the dynamic models
  // (drawn exactly on top), nor the retained fade (scaled in the resolve).
  std::vector<double> CacheSignature(const View& view, const std::vector<ProjectorPass>& passes,
                                     const std::vector<char>& visible) const {
    std::vector<double> sig = StaticSignature(view);
    for (size_t k = 0; k < passes.size(); ++k) {
      if (!visible[k]) continue;
      const ProjectorPass& pass = passes[k];
      const Projector& p = *pass.projector;
      sig.insert(sig.end(), {double(pass.retained), double(pass.layer), p.near_m, p.far_m});
      if (pass.retained) sig.push_back(double(retained[pass.layer].order));
      AppendMatrix(p.view, sig);
      AppendMatrix(p.projection, sig);
      sig.insert(sig.end(), p.distortion.begin(), p.distortion.end());
      for (const Eigen::Vector3d& c : pass.corners) sig.insert(sig.end(), c.data(), c.data() + 3);
    }
    return sig;
  }

  // The part of CacheSignature that is the view's own (what its static G-buffer depends on, and
  // the display options).
  std::vector<double> StaticSignature(const View& view) const {
    std::vector<double> sig;
    const Viewport& v = view.viewport;
    const DisplayOptions& display = options.display;
    sig.insert(sig.end(), {double(target_width), double(target_height), double(v.x), double(v.y), double(v.width),
                           double(v.height), double(static_version), double(static_cast<int>(display.overlap)),
                           display.seam_feather, display.retention_half_life_s, double(display.sky)});
    sig.insert(sig.end(), view.clear_color.data(), view.clear_color.data() + 3);
    AppendMatrix(view.view, sig);
    AppendMatrix(view.projection, sig);
    return sig;
  }

  // Draws a still view's cache: the static G-buffer, the mapping of the live passes (image
  // load/store, a barrier between projectors) and the retained accumulation.
  void BuildViewCache(const View& view, const std::vector<ProjectorPass>& passes, const std::vector<char>& visible,
                      ViewCache& cache) {
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_cache_gbuffer);
    ApplyPassState(Pass::kGbuffer);
    glClearColor(0, 0, 0, 0);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    DrawGbuffer(view, /*with_static=*/true, /*with_dynamic=*/false);
    cache.static_signature = StaticSignature(view);
    cache.static_valid = true;
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_mapping);
    ApplyPassState(Pass::kGbuffer);
    if (cache.any_live) glClear(GL_COLOR_BUFFER_BIT);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_cache_accum);
    const GLenum retained_buffers[] = {GL_NONE, GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2};
    glDrawBuffers(3, retained_buffers);
    if (cache.any_retained) glClear(GL_COLOR_BUFFER_BIT);
    const GLenum no_buffers[] = {GL_NONE, GL_NONE};
    glDrawBuffers(2, no_buffers);
    if (cache.any_live) {
      BindProjectorInputs(view, mapping, cache_normal, cache_depth);
      BindTexture(kShadowUnit, GL_TEXTURE_2D_ARRAY, live_shadows.static_array);
      glBindImageTexture(kMappingImageUnit, mapping_array, 0, GL_TRUE, 0, GL_READ_WRITE, GL_RGBA32F);
      glUniform1i(mapping.u["u_mapping"], static_cast<GLint>(kMappingImageUnit));
      ApplyPassState(Pass::kProjector);
      const bool last_wins = options.display.overlap == OverlapPolicy::kLastWins;
      for (size_t k = 0; k < passes.size(); ++k) {
        if (!visible[k] || passes[k].retained) continue;
        DrawPass(mapping.u, passes[k], k, last_wins);
        glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
      }
      glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
    }
    if (cache.any_retained) {
      BindProjectorInputs(view, projector, cache_normal, cache_depth);
      DrawRetainedPasses(passes, visible);
    }
    cache.built_s = Now();
  }

  // Stencil > 0 (within the current scissor box, cleared first) where the surface in the depth
  // buffer lies inside some live projector's shadow volume: the only pixels whose cached entries
  // the models may hide.
  void MarkShadowVolumes(const View& view) {
    glStencilMask(0xFF);
    glClearStencil(0);
    glClear(GL_STENCIL_BUFFER_BIT);
    if (shadow_volume_count == 0) return;
    ApplyPassState(Pass::kMark);
    glUseProgram(line_program);
    glUniformMatrix4fv(line_clip_from_local, 1, GL_FALSE, ToGlArray(view.projection * view.view).data());
    volumes.Draw(GL_TRIANGLES, shadow_volume_first, shadow_volume_count);
  }

  // The screen rectangles of a view around the dynamic models' boxes (drawn exactly over a cached
  // view), merged so that none overlap.
  std::vector<Viewport> ModelRects(const View& view) const {
    std::vector<Viewport> rects;
    const Eigen::Matrix4d clip_from_local = view.projection * view.view;
    for (const Bounds& box : model_bounds) {
      std::vector<Eigen::Vector4d> points;
      for (const Eigen::Vector3d& c : box.Corners()) points.push_back(c.homogeneous());
      if (const std::optional<Viewport> rect = ScreenRect(points, clip_from_local, view.viewport)) rects.push_back(*rect);
    }
    MergeOverlapping(rects);
    return rects;
  }

  // Merges overlapping rectangles until none overlap (each pixel drawn once).
  static void MergeOverlapping(std::vector<Viewport>& rects) {
    for (bool merged = true; merged;) {
      merged = false;
      for (size_t a = 0; a < rects.size() && !merged; ++a) {
        for (size_t b = a + 1; b < rects.size() && !merged; ++b) {
          if (!Overlap(rects[a], rects[b])) continue;
          rects[a] = Union(rects[a], rects[b]);
          rects.erase(rects.begin() + static_cast<std::ptrdiff_t>(b));
          merged = true;
        }
      }
    }
  }

  // The working G-buffer of a view, then its projector passes and resolve: the full frame.
  // scale > 1 (a moving view, MovingViewScale): drawn at that fraction of the viewport's width and
  // height and scaled up in the resolve; the view's slot records it for ReadLinearDepth.
  // static_from_cache: the view's static G-buffer is taken (scaled, nearest) from its view cache
  // instead of drawn: only projectors changed (a turning camera), the view did not.
  void DrawViewExact(const View& view, const std::vector<ProjectorPass>& passes, const std::vector<char>& visible,
                     bool any_live, bool any_retained, GLuint target, double scale = 1,
                     bool static_from_cache = false) {
    View drawn = view;
    Viewport& d = drawn.viewport;
    d.width = std::max(1, static_cast<int>(std::ceil(view.viewport.width / scale)));
    d.height = std::max(1, static_cast<int>(std::ceil(view.viewport.height / scale)));
    const bool smaller = d.width != view.viewport.width || d.height != view.viewport.height;
    glViewport(d.x, d.y, d.width, d.height);
    glScissor(d.x, d.y, d.width, d.height);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_gbuffer);
    ApplyPassState(Pass::kGbuffer);
    if (static_from_cache) {
      CopyCachedGbuffer(view.viewport, d);
      ++stats.views_static_from_cache;
    } else {
      glClearColor(0, 0, 0, 0);
      glClearDepth(1.0);
      glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    }
    DrawGbuffer(drawn, /*with_static=*/!static_from_cache, /*with_dynamic=*/true);
    AccumulateAndResolve(drawn, passes, visible, any_live, any_retained, target, smaller ? &view : nullptr);
    if (smaller) reduced_views.push_back({view.viewport, d});
    ++stats.views_uncached;
    if (smaller) ++stats.views_reduced;
  }

  // The view cache's static G-buffer under `from` into the working G-buffer under `to` (the same
  // corner, maybe smaller: nearest), colour, normal and depth; leaves the working G-buffer bound.
  void CopyCachedGbuffer(const Viewport& from, const Viewport& to) {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_cache_gbuffer);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_gbuffer);
    for (GLenum attachment : {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1}) {
      glReadBuffer(attachment);
      const GLenum one[] = {attachment == GL_COLOR_ATTACHMENT0 ? attachment : GLenum{GL_NONE},
                            attachment == GL_COLOR_ATTACHMENT1 ? attachment : GLenum{GL_NONE}};
      glDrawBuffers(2, one);
      glBlitFramebuffer(from.x, from.y, from.x + from.width, from.y + from.height, to.x, to.y, to.x + to.width,
                        to.y + to.height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    }
    glBlitFramebuffer(from.x, from.y, from.x + from.width, from.y + from.height, to.x, to.y, to.x + to.width,
                      to.y + to.height, GL_DEPTH_BUFFER_BIT, GL_NEAREST);
    const GLenum both[] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1};
    glDrawBuffers(2, both);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_gbuffer);
  }

  // RendererOptions::moving_view_scale, and more where the view sees more live cameras than
  // moving_view_cameras (the per-pixel work grows with them): up to kMaxMovingViewScale.
  double MovingViewScale(const std::vector<ProjectorPass>& passes, const std::vector<char>& visible) const {
    if (options.moving_view_scale <= 1) return 1;  // full resolution always
    int live = 0;
    for (size_t k = 0; k < passes.size(); ++k) live += visible[k] && !passes[k].retained;
    const double scale =
        options.moving_view_scale * std::sqrt(std::max(1.0, static_cast<double>(live) / options.moving_view_cameras));
    return std::min(scale, std::max(options.moving_view_scale, kMaxMovingViewScale));
  }

  // A still view: its cache resolved against the current video, then the rectangles dynamic
  // models touch drawn exactly over it. The cache is rebuilt when its signature changed and the
  // view's inputs were the same in the previous frame (or there was none); while they change from
  // frame to frame (a flying browse view, a turning camera) the view is drawn in full instead,
  // which costs less than a build that the next frame would throw away.
  void DrawViewCached(size_t slot, const std::vector<View>& views, const std::vector<ProjectorPass>& passes,
                      const std::vector<char>& visible, bool any_live, bool any_retained, GLuint target) {
    const View& view = views[slot];
    if (view_caches.size() < views.size()) view_caches.resize(views.size());
    ViewCache& cache = view_caches[slot];
    std::vector<double> signature = CacheSignature(view, passes, visible);
    const bool still = cache.last_signature.empty() || cache.last_signature == signature;
    cache.last_signature = signature;
    if ((!cache.valid || cache.signature != signature) && !still) {
      // Only projectors changed (a camera turning): the cached static G-buffer still holds.
      const bool static_kept = cache.static_valid && cache.static_signature == StaticSignature(view);
      cache.valid = false;
      DrawViewExact(view, passes, visible, any_live, any_retained, target, MovingViewScale(passes, visible),
                    static_kept);
      return;
    }
    if (!cache.valid || cache.signature != signature) {
      // The cache textures are shared: another slot's cache under this viewport is lost.
      for (size_t k = 0; k < view_caches.size(); ++k) {
        if (k != slot && Overlap(view_caches[k].viewport, view.viewport)) {
          view_caches[k].valid = view_caches[k].static_valid = false;
        }
      }
      cache.valid = true;
      cache.viewport = view.viewport;
      cache.signature = std::move(signature);
      cache.any_live = any_live;
      cache.any_retained = any_retained;
      BuildViewCache(view, passes, visible, cache);
      ++stats.view_cache_builds;
    } else {
      ++stats.view_cache_hits;
    }
    // Where a model is in a visible live projector's shadow map, the cached entries are tested
    // against it (only those whose video falls where the models are in that projector's image).
    bool shadowed = false;
    int visible_live = 0;
    for (size_t k = 0; k < passes.size(); ++k) {
      if (!visible[k] || passes[k].retained) continue;
      ++visible_live;
      if (slots[passes[k].layer].shadow.dynamic_has_models) shadowed = true;
    }
    shadowed = shadowed && cache.any_live && options.dynamic_objects_cast_shadows;
    glBindFramebuffer(GL_FRAMEBUFFER, target);
    Resolve(view, cache.any_live, cache.any_retained, &cache);
    if (shadowed) {
      MarkShadowVolumes(view);
      // Inside the volumes, keep only pixels with an entry the models may hide. That pass runs on
      // every pixel of the view (a shader that discards and writes stencil gets no early stencil
      // test on llvmpipe), so it pays only where the view sees more cameras than a pixel keeps
      // entries: with fewer, every volume that holds the surface has its entry there anyway.
      const bool by_entries = visible_live > options.view_cache_entries;
      if (by_entries) {
        Resolve(view, cache.any_live, cache.any_retained, &cache, &passes, nullptr, Pass::kMarkEntries);
        ++stats.view_cache_entry_marks;
      }
      Resolve(view, cache.any_live, cache.any_retained, &cache, &passes, nullptr,
              by_entries ? Pass::kResolveMarked : Pass::kResolveInVolumes);
      ++stats.view_cache_shadow_tests;
    }
    cache.patches = ModelRects(view);
    cache.last_frame = stats.frames + 1;

    for (const Viewport& r : cache.patches) {
      glScissor(r.x, r.y, r.width, r.height);
      for (const auto& [from, to] : {std::pair{cache_color, gbuffer_color}, std::pair{cache_normal, gbuffer_normal},
                                     std::pair{cache_depth, gbuffer_depth}}) {
        glCopyImageSubData(from, GL_TEXTURE_2D, 0, r.x, r.y, 0, to, GL_TEXTURE_2D, 0, r.x, r.y, 0, r.width, r.height, 1);
      }
      glBindFramebuffer(GL_FRAMEBUFFER, fbo_gbuffer);
      DrawGbuffer(view, /*with_static=*/false, /*with_dynamic=*/true);
      AccumulateAndResolve(view, passes, visible, any_live, any_retained, target);
      ++stats.view_cache_patches;
    }
    const Viewport& v = view.viewport;
    glScissor(v.x, v.y, v.width, v.height);
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
                                  ProgramSpec{&impl->line_program, "shaders/line.vert.glsl", "shaders/line.frag.glsl"}}) {
    absl::StatusOr<GLuint> program = internal::BuildEmbeddedProgram(spec.vertex, spec.fragment);
    if (!program.ok()) return program.status();
    *spec.program = *program;
  }
  impl->gbuffer_u = Uniforms(impl->gbuffer_program, {"u_clip_from_local", "u_sun_direction", "u_ambient", "u_diffuse",
                                                     "u_sky_color"});
  // The view cache needs image load/store (4.2) and glCopyImageSubData (4.3).
  impl->cache_supported = major * 10 + minor >= 43;
  const std::string entries = "#define ENTRIES " + std::to_string(options.view_cache_entries) + "\n";
  auto build = [](Program& out, const char* vertex, const char* fragment, const std::string& defines,
                  std::initializer_list<const char*> names) -> absl::Status {
    absl::StatusOr<GLuint> program = internal::BuildEmbeddedProgram(vertex, fragment, defines);
    if (!program.ok()) return program.status();
    out.id = *program;
    out.u = Uniforms(out.id, names);
    return absl::OkStatus();
  };
  const std::initializer_list<const char*> projector_names = {
      "u_gbuffer_normal", "u_gbuffer_depth", "u_view_clip_from_local", "u_local_from_window",
      "u_clip_from_local", "u_shadow_clip_from_local", "u_shadow_widen",
      "u_projector_position", "u_pinhole", "u_k1_k2_p1_p2", "u_k3", "u_distorted", "u_layer", "u_normal_offset",
      "u_feather", "u_best_view", "u_last_wins", "u_fade", "u_weight_scale", "u_video", "u_shadow", "u_mapping"};
  if (absl::Status s = build(impl->projector, "shaders/projector.vert.glsl", "shaders/projector.frag.glsl", "",
                             projector_names);
      !s.ok()) {
    return s;
  }
  if (absl::Status s = build(impl->combined, "shaders/resolve.vert.glsl", "shaders/projector.frag.glsl",
                             "#define COMBINED\n#define BATCH " + std::to_string(kCombinedBatch) + "\n",
                             {"u_gbuffer_normal", "u_gbuffer_depth", "u_local_from_window", "u_feather", "u_best_view",
                              "u_last_wins", "u_weight_scale", "u_video", "u_shadow", "u_count", "u_clips",
                              "u_shadow_clips", "u_pinholes", "u_distortions", "u_position_layers", "u_extras"});
      !s.ok()) {
    return s;
  }
  if (impl->cache_supported) {
    const std::string defines = "#extension GL_ARB_shader_image_load_store : require\n#define MAPPING\n" + entries;
    if (absl::Status s = build(impl->mapping, "shaders/projector.vert.glsl", "shaders/projector.frag.glsl", defines,
                               projector_names);
        !s.ok()) {
      return s;
    }
  }
  for (int variant = 0; variant < (impl->cache_supported ? 32 : 4); ++variant) {
    if ((variant & 8) && (variant & 5) != 5) continue;
    if ((variant & 16) && !(variant & 8)) continue;
    const std::string defines = std::string(variant & 1 ? "#define LIVE\n" : "") +
                                (variant & 2 ? "#define RETAINED\n" : "") + (variant & 4 ? "#define CACHED\n" : "") +
                                (variant & 8 ? "#define SHADOWED\n" : "") + (variant & 16 ? "#define MARK\n" : "") + entries + "#define MAX_PROJECTORS " +
                                std::to_string(kMaxProjectors) + "\n";
    if (absl::Status s = build(impl->resolve[variant], "shaders/resolve.vert.glsl", "shaders/resolve.frag.glsl", defines,
                               {"u_gbuffer_color", "u_gbuffer_depth", "u_live", "u_retained", "u_fade", "u_clear_color",
                                "u_tint_by_age", "u_fade_scale", "u_mapping", "u_video", "u_last_wins",
                                "u_gbuffer_normal", "u_local_from_window", "u_shadow", "u_shadow_clip_from_local",
                                "u_position_offset", "u_model_uv", "u_source_origin", "u_source_scale"});
        !s.ok()) {
      return s;
    }
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
                      &impl->fbo_gbuffer, &impl->fbo_accum, &impl->fbo_cache_gbuffer, &impl->fbo_cache_accum,
                      &impl->fbo_mapping}) {
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
      if (old != nullptr && MatricesFinite(*old) &&
          ReprojectionShiftPx(*old, p, d.options.frustum_depth_m, d.options.video_layer_width,
                              d.options.video_layer_height) < d.options.still_pose_tolerance_px) {
        // Jitter of a still camera: keep the pose its shadow map and the view caches were made with.
        p.view = old->view;
        p.projection = old->projection;
        p.position = old->position;
        p.near_m = old->near_m;
        p.far_m = old->far_m;
      }
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
  std::vector<Bounds> model_bounds(models.size());
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
    model_bounds[k].Add(m.base - Eigen::Vector3d(reach, reach, 0));
    model_bounds[k].Add(m.base + Eigen::Vector3d(reach, reach, m.size.z()));
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
  d.model_bounds = std::move(model_bounds);
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
  // Then the live projectors' shadow volumes of the dynamic models (the stencil of cached views).
  d.shadow_volume_first = static_cast<GLint>(volume_vertices.size());
  if (d.options.dynamic_objects_cast_shadows) {
    for (const ProjectorPass& pass : passes) {
      if (pass.retained) continue;
      AppendShadowVolumes(*pass.projector, d.slots[pass.layer].shadow, d.model_bounds, scene,
                          d.options.shadow_map_size, volume_vertices);
    }
  }
  d.shadow_volume_count = static_cast<GLsizei>(volume_vertices.size()) - d.shadow_volume_first;
  d.volumes.Upload(volume_vertices, GL_STREAM_DRAW);
  d.reduced_views.clear();

  if (d.view_caches.size() > views.size()) d.view_caches.resize(views.size());
  for (size_t slot = 0; slot < views.size(); ++slot) {
    const View& view = views[slot];
    const Viewport& v = view.viewport;
    const Eigen::Matrix4d clip_from_local = view.projection * view.view;
    glViewport(v.x, v.y, v.width, v.height);
    glScissor(v.x, v.y, v.width, v.height);
    bool any_live = false, any_retained = false;
    std::vector<char> visible(passes.size());
    for (size_t k = 0; k < passes.size(); ++k) {
      visible[k] = VolumeMayBeVisible(passes[k].corners, clip_from_local);
      if (!visible[k]) ++d.stats.projectors_culled;
      (passes[k].retained ? any_retained : any_live) |= static_cast<bool>(visible[k]);
    }
    // Views that share pixels with another view of this call cannot keep a cache (shared targets).
    bool cached = d.CacheOn();
    for (size_t k = 0; k < views.size() && cached; ++k) cached = k == slot || !Overlap(views[k].viewport, v);
    if (cached) {
      d.DrawViewCached(slot, views, passes, visible, any_live, any_retained, target);
    } else {
      if (slot < d.view_caches.size()) d.view_caches[slot] = ViewCache();
      d.DrawViewExact(view, passes, visible, any_live, any_retained, target);
    }
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
  // A view drawn from its cache in the last frame: the cached G-buffer, and the working one in the
  // rectangles drawn exactly over it.
  std::vector<std::pair<GLuint, Viewport>> sources = {{d.fbo_gbuffer, v}};
  for (const ViewCache& cache : d.view_caches) {
    if (!cache.valid || cache.last_frame != d.stats.frames || cache.viewport.x != v.x || cache.viewport.y != v.y ||
        cache.viewport.width != v.width || cache.viewport.height != v.height) {
      continue;
    }
    sources = {{d.fbo_cache_gbuffer, v}};
    for (const Viewport& r : cache.patches) sources.emplace_back(d.fbo_gbuffer, r);
  }
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glPixelStorei(GL_PACK_ROW_LENGTH, v.width);
  for (const auto& [fbo, r] : sources) {
    const size_t offset = static_cast<size_t>(r.y - v.y) * v.width + (r.x - v.x);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    glReadPixels(r.x, r.y, r.width, r.height, GL_DEPTH_COMPONENT, GL_FLOAT, window_depth.data() + offset);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(r.x, r.y, r.width, r.height, GL_RGBA, GL_UNSIGNED_BYTE, color.data() + 4 * offset);
  }
  glPixelStorei(GL_PACK_ROW_LENGTH, 0);
  // A view drawn at reduced resolution: its working G-buffer part, scaled up as the resolve did.
  for (const auto& [shown, drawn] : d.reduced_views) {
    if (shown.x != v.x || shown.y != v.y || shown.width != v.width || shown.height != v.height) continue;
    std::vector<float> small_depth(static_cast<size_t>(drawn.width) * drawn.height);
    std::vector<uint8_t> small_color(small_depth.size() * 4);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, d.fbo_gbuffer);
    glReadPixels(drawn.x, drawn.y, drawn.width, drawn.height, GL_DEPTH_COMPONENT, GL_FLOAT, small_depth.data());
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(drawn.x, drawn.y, drawn.width, drawn.height, GL_RGBA, GL_UNSIGNED_BYTE, small_color.data());
    for (int row = 0; row < v.height; ++row) {
      const int src_row = std::min(drawn.height - 1, static_cast<int>((row + 0.5) * drawn.height / v.height));
      for (int col = 0; col < v.width; ++col) {
        const int src_col = std::min(drawn.width - 1, static_cast<int>((col + 0.5) * drawn.width / v.width));
        const size_t src = static_cast<size_t>(src_row) * drawn.width + src_col;
        const size_t dst = static_cast<size_t>(row) * v.width + col;
        window_depth[dst] = small_depth[src];
        std::copy_n(&small_color[4 * src], 4, &color[4 * dst]);
      }
    }
  }
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
