#include "viewer_client/render/passes/projector_geometry.h"

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "model_store/geometry/camera.h"

namespace ave::viewer::internal {

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

std::array<Eigen::Vector3d, 4> FrustumCorners(const Eigen::Matrix4d& local_from_eye, const Eigen::Matrix4d& eye_from_clip,
                                              double scale, double depth_m) {
  return FrustumCorners(local_from_eye, eye_from_clip, Eigen::Vector4d(-scale, -scale, scale, scale), depth_m);
}

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

double DistortionMargin(const Projector& p) {
  if (!HasDistortion(p)) return 1;
  const double sum = std::abs(p.distortion[0]) + std::abs(p.distortion[1]) + std::abs(p.distortion[4]) +
                     std::abs(p.distortion[2]) + std::abs(p.distortion[3]);
  return std::clamp(1 + 2 * sum, 1.0, 2.0);
}

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

Eigen::Vector4d ModelNdcRect(const Projector& p, const Viewport& rect, int shadow_map_size) {
  const double pad = kNormalOffsetTexels + 2, margin = DistortionMargin(p);
  return margin * Eigen::Vector4d(2 * (rect.x - pad) / shadow_map_size - 1, 2 * (rect.y - pad) / shadow_map_size - 1,
                                  2 * (rect.x + rect.width + pad) / shadow_map_size - 1,
                                  2 * (rect.y + rect.height + pad) / shadow_map_size - 1);
}

void SetDeepestTiles(const std::vector<float>& depth, int size, ShadowSlot& slot) {
  const int side = (size + kDeepestTile - 1) / kDeepestTile;
  slot.deepest_tiles_side = side;
  slot.deepest_tiles.assign(static_cast<size_t>(side) * side, 0.0f);
  for (int row = 0; row < size; ++row) {
    float* tiles = slot.deepest_tiles.data() + static_cast<size_t>(row / kDeepestTile) * side;
    const float* line = depth.data() + static_cast<size_t>(row) * size;
    for (int col = 0; col < size; ++col) tiles[col / kDeepestTile] = std::max(tiles[col / kDeepestTile], line[col]);
  }
}

double StaticDeepestM(const ShadowSlot& slot, const Viewport& rect, const Eigen::Matrix4d& shadow_projection) {
  const int side = slot.deepest_tiles_side;
  if (side <= 0 || slot.deepest_tiles.size() != static_cast<size_t>(side) * side) {
    return std::numeric_limits<double>::infinity();
  }
  const int pad = static_cast<int>(std::ceil(kNormalOffsetTexels)) + 2;
  const int x0 = std::clamp((rect.x - pad) / kDeepestTile, 0, side - 1);
  const int y0 = std::clamp((rect.y - pad) / kDeepestTile, 0, side - 1);
  const int x1 = std::clamp((rect.x + rect.width + pad) / kDeepestTile, 0, side - 1);
  const int y1 = std::clamp((rect.y + rect.height + pad) / kDeepestTile, 0, side - 1);
  float deepest = 0;
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) deepest = std::max(deepest, slot.deepest_tiles[static_cast<size_t>(y) * side + x]);
  }
  if (deepest >= 1.0f) return std::numeric_limits<double>::infinity();
  const Eigen::Vector4d eye = shadow_projection.inverse() * Eigen::Vector4d(0, 0, 2.0 * deepest - 1, 1);
  return -eye.z() / eye.w();
}

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

std::vector<Viewport> CoveringTiles(const std::vector<Viewport>& rects, const Viewport& viewport, int tile) {
  const int columns = (viewport.width + tile - 1) / tile, rows = (viewport.height + tile - 1) / tile;
  std::vector<uint8_t> covered(static_cast<size_t>(columns) * rows, 0);
  for (const Viewport& r : rects) {
    if (!Overlap(r, viewport)) continue;
    const Viewport c = Intersection(r, viewport);
    const int c0 = (c.x - viewport.x) / tile, c1 = (c.x + c.width - 1 - viewport.x) / tile;
    const int r0 = (c.y - viewport.y) / tile, r1 = (c.y + c.height - 1 - viewport.y) / tile;
    for (int row = r0; row <= r1; ++row) {
      std::fill(covered.begin() + row * columns + c0, covered.begin() + row * columns + c1 + 1, 1);
    }
  }
  std::vector<Viewport> out;
  std::vector<size_t> previous_row, this_row;  // indices into out of the runs ending at the row
  for (int row = 0; row < rows; ++row) {
    this_row.clear();
    for (int col = 0; col < columns;) {
      if (!covered[row * columns + col]) {
        ++col;
        continue;
      }
      int end = col;
      while (end < columns && covered[row * columns + end]) ++end;
      const int x = viewport.x + col * tile, y = viewport.y + row * tile;
      const Viewport run{x, y, std::min(end * tile, viewport.width) - col * tile,
                         std::min((row + 1) * tile, viewport.height) - row * tile};
      bool joined = false;
      for (size_t k : previous_row) {
        Viewport& above = out[k];
        if (above.x == run.x && above.width == run.width && above.y + above.height == run.y) {
          above.height += run.height;
          this_row.push_back(k);
          joined = true;
          break;
        }
      }
      if (!joined) {
        out.push_back(run);
        this_row.push_back(out.size() - 1);
      }
      col = end;
    }
    std::swap(previous_row, this_row);
  }
  return out;
}

std::optional<Viewport> BoxesScreenRect(std::span<const Bounds> boxes, const Eigen::Matrix4d& clip_from_local,
                                        const Viewport& viewport) {
  std::vector<Eigen::Vector4d> points;
  for (const Bounds& b : boxes) {
    for (const Eigen::Vector3d& c : b.Corners()) points.push_back(c.homogeneous());
  }
  return ScreenRect(points, clip_from_local, viewport);
}

}  // namespace ave::viewer::internal
