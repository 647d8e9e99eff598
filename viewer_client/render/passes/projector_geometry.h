#pragma once
// Internal to ave_render: CPU geometry the passes share (no GL calls): boxes, projector frusta and
// their volumes, screen rectangles, the shadow-map facts a projector's footprint is bounded by.
// Everything in the model's local frame (metres), like renderer.h.
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

// Normal offset for the shadow lookup, in shadow-map texels at the fragment's distance.
inline constexpr float kNormalOffsetTexels = 1.0f;

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

// Rendered shadow map state of one layer (ShadowMaps writes it; footprints and the resolve read it).
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
  // The static shadow map's deepest window depth per kDeepestTile x kDeepestTile texels (rows from
  // the bottom; 1 where some texel sees nothing), with the read-back above; empty when not read.
  // Cuts the models' shadow volumes where the surface behind them ends (issue 17).
  std::vector<float> deepest_tiles;
  int deepest_tiles_side = 0;
};

inline constexpr int kDeepestTile = 16;
// The tiles of ShadowSlot::deepest_tiles from a static shadow map read back (size x size, rows from
// the bottom).
void SetDeepestTiles(const std::vector<float>& depth, int size, ShadowSlot& slot);
// How far (depth along the projector's axis, metres) the static surface reaches behind the
// shadow-map rectangle `rect` (pixels), padded as ModelNdcRect pads it: +infinity where unknown
// (not read back, or some texel there sees nothing).
double StaticDeepestM(const ShadowSlot& slot, const Viewport& rect, const Eigen::Matrix4d& shadow_projection);

// A triangle wound counter-clockwise as seen from the side `outward` points to.
template <typename V, typename Make>
void AppendOrientedTriangle(const Eigen::Vector3d& a, Eigen::Vector3d b, Eigen::Vector3d c,
                            const Eigen::Vector3d& outward, std::vector<V>& out, Make make) {
  if ((b - a).cross(c - a).dot(outward) < 0) std::swap(b, c);
  out.push_back(make(a));
  out.push_back(make(b));
  out.push_back(make(c));
}

// The corners of the image rectangle `ndc_rect` (x0, y0, x1, y1) at depth_m along the optical
// axis, counter-clockwise from bottom-left.
std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              const Eigen::Vector4d& ndc_rect, double depth_m);
// The image (NDC scaled by `scale`; 1: the image rectangle) at depth_m.
std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              double scale, double depth_m);
// Camera centre to the four image corners at depth_m along the optical axis, plus the rectangle.
std::array<Eigen::Vector3d, 16> FrustumSegments(const Projector& p, double depth_m);

bool HasDistortion(const Projector& p);
// How far beyond the undistorted image the distorted frame may reach (NDC factor): the shadow map
// and the footprint are widened by it. Barrel distortion (k1 < 0) pulls a wider field into the
// frame; this bound covers |k| sums up to 0.5 (the frame corners of common wide lenses).
double DistortionMargin(const Projector& p);
// How far (pixels of a layer_width x layer_height image) the image centre and corners at depth_m
// in front of `from` move when seen through `to` instead: 0 for the same pose.
double ReprojectionShiftPx(const Projector& from, const Projector& to, double depth_m, int layer_width,
                           int layer_height);
bool MatricesFinite(const Projector& p);

// The shadow-map rectangle `rect` (pixels) where a projector's dynamic layer may differ from its
// static one, as (x0, y0, x1, y1) in the projector's own undistorted NDC, padded for the normal
// offset and the 2x2 comparison filter of the lookups.
Eigen::Vector4d ModelNdcRect(const Projector& p, const Viewport& rect, int shadow_map_size);
// Where a projector's (distorted) image, as video (u, v) of its layer, may show the dynamic models
// its shadow map holds in `rect` (ModelNdcRect): an entry whose (u, v) lies outside sees the static
// shadow map only. The distortion is bounded over a grid of the rectangle (the forward model
// evaluated as the projector shader does).
Eigen::Vector4f ModelUvRect(const Projector& p, const Viewport& rect, int shadow_map_size, int layer_width,
                            int layer_height);

// A projector's matrices and lens as the shaders take them.
struct ProjectorGl {
  GlMatrix clip_from_local{}, shadow_clip_from_local{};
  Eigen::Matrix4d shadow_projection = Eigen::Matrix4d::Identity();  // widened by the distortion margin
  float pinhole[4] = {0, 0, 0, 0};
  float distortion[5] = {0, 0, 0, 0, 0};
  bool distorted = false;
  float normal_offset = 0;
};
ProjectorGl MakeProjectorGl(const Projector& p, int shadow_map_size);

// A frustum piece between the rectangles near_c and far_c (corners in the same order): 12
// triangles wound counter-clockwise from outside.
void AppendFrustumPiece(const std::array<Eigen::Vector3d, 4>& near_c, const std::array<Eigen::Vector3d, 4>& far_c,
                        std::vector<LineVertex>& out);
// Where a projector's volume ends (depth along its axis): at the farthest scene point, or nearer
// where its static shadow map saw no farther surface.
double VolumeFarM(const Projector& p, const Bounds& scene, const ShadowSlot& shadow);
// The frustum volume of a projector, cut at VolumeFarM (fewer pixels to shade) and widened by the
// distortion margin: 12 triangles wound counter-clockwise from outside.
void AppendFrustumVolume(const Projector& p, const Bounds& scene, const ShadowSlot& shadow, std::vector<LineVertex>& out,
                         std::array<Eigen::Vector3d, 8>& corners_out);
// False when all eight corners lie outside one clip plane of the view (the volume cannot show).
bool VolumeMayBeVisible(const std::array<Eigen::Vector3d, 8>& corners, const Eigen::Matrix4d& clip_from_local);

// Screen rectangles in framebuffer pixels (GL convention, like Viewport).
bool Overlap(const Viewport& a, const Viewport& b);
Viewport Union(const Viewport& a, const Viewport& b);
Viewport Intersection(const Viewport& a, const Viewport& b);
// Disjoint rectangles of `tile`-pixel squares (from the viewport's corner, clipped to it) that
// cover every pixel of `rects`: runs of squares along rows, equal runs of adjacent rows joined.
// Scattered rectangles (a crowd) do not grow into their union, as merging overlapping ones did.
std::vector<Viewport> CoveringTiles(const std::vector<Viewport>& rects, const Viewport& viewport, int tile);
// The pixels of `viewport` that the convex hull of the points may cover in a view with this
// matrix, padded by two pixels. Points are homogeneous: w = 0 is a direction, standing for the
// whole ray towards it from the other points (its image ends at the direction's vanishing point).
// The whole viewport when a point or direction lies behind the eye (it cannot be bounded there).
std::optional<Viewport> ScreenRect(const std::vector<Eigen::Vector4d>& points, const Eigen::Matrix4d& clip_from_local,
                                   const Viewport& viewport);
// ScreenRect of the corners of boxes.
std::optional<Viewport> BoxesScreenRect(std::span<const Bounds> boxes, const Eigen::Matrix4d& clip_from_local,
                                        const Viewport& viewport);

}  // namespace ave::viewer::internal
