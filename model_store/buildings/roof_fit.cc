#include "model_store/buildings/roof_fit.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_format.h"

namespace ave::model::internal {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr int kMinPoints = 6;

void FlatBasis(const Rect2&, const Vector2d&, Eigen::Ref<Eigen::VectorXd> row) { row(0) = 1; }
void PlaneBasis(const Rect2&, const Vector2d& uv, Eigen::Ref<Eigen::VectorXd> row) {
  row << 1, uv.x(), uv.y();
}
// Ridge along the rectangle's x axis (the scene's gable convention), rise over half the y size.
void GableBasis(const Rect2& r, const Vector2d& uv, Eigen::Ref<Eigen::VectorXd> row) {
  row << 1, std::max(0.0, 1 - std::abs(uv.y()) / r.half.y());
}
// Four slopes meeting along the longer axis: the rise is reached a short half-size in.
void HipBasis(const Rect2& r, const Vector2d& uv, Eigen::Ref<Eigen::VectorXd> row) {
  const double h_short = std::min(r.half.x(), r.half.y());
  row << 1, std::max(0.0, std::min(r.half.x() - std::abs(uv.x()), r.half.y() - std::abs(uv.y())) / h_short);
}

// The same rectangle with its axes turned by 90 degrees (x becomes the old y).
Rect2 Turned(const Rect2& r) {
  Rect2 t = r;
  t.half = Vector2d(r.half.y(), r.half.x());
  t.yaw_rad = r.yaw_rad + std::numbers::pi / 2;
  return t;
}

// Candidate roof on a rectangular footprint: its fit, model complexity and how it reads as a part.
struct Candidate {
  RoofType roof = RoofType::kFlat;
  Rect2 rect;
  LinearFit fit;
  int params = 1;
};

std::vector<Vector2d> RectCorners(const Rect2& r) {
  const double c = std::cos(r.yaw_rad), s = std::sin(r.yaw_rad);
  const Vector2d ax(c, s), ay(-s, c);
  std::vector<Vector2d> out;
  for (const auto& [sx, sy] : {std::pair{-1, -1}, {1, -1}, {1, 1}, {-1, 1}})
    out.push_back(r.center + sx * r.half.x() * ax + sy * r.half.y() * ay);
  return out;
}

BuildingPrimitive PrimitiveFromRect(const Rect2& r, PrimitiveType type, RoofType roof) {
  BuildingPrimitive p;
  p.type = type;
  p.roof = roof;
  p.center_m = r.center;
  p.size_m = 2 * r.half;
  p.yaw_rad = std::remainder(r.yaw_rad, 2 * std::numbers::pi);
  return p;
}

// A plane z = c0 + a u + b v read as a shed: the part's +y axis points uphill along the nearer
// rectangle axis, eaves on the low (-y) edge.
BuildingPrimitive ShedFromPlane(const Rect2& rect, const Eigen::VectorXd& c) {
  Rect2 r = rect;
  double slope_y = c(2), slope_x = c(1);
  if (std::abs(slope_x) > std::abs(slope_y)) {
    // Uphill along the old x: turn by -90 degrees so the new +y is the old +x.
    r.half = Vector2d(rect.half.y(), rect.half.x());
    r.yaw_rad = rect.yaw_rad - std::numbers::pi / 2;
    slope_y = slope_x;
  }
  if (slope_y < 0) {
    r.yaw_rad += std::numbers::pi;
    slope_y = -slope_y;
  }
  BuildingPrimitive p = PrimitiveFromRect(r, PrimitiveType::kWedge, RoofType::kShed);
  p.eave_height_m = c(0) - slope_y * r.half.y();  // absolute for now; made relative by the caller
  p.roof_height_m = 2 * slope_y * r.half.y();
  return p;
}

absl::StatusOr<Candidate> FitCandidate(const std::vector<Vector3d>& pts, const Rect2& rect, RoofType roof) {
  Candidate cand{roof, rect, {}, 1};
  absl::StatusOr<LinearFit> fit;
  switch (roof) {
    case RoofType::kFlat:
    case RoofType::kCylinder: fit = FitLinearRoof(pts, rect, 1, &FlatBasis); break;
    case RoofType::kShed: fit = FitLinearRoof(pts, rect, 3, &PlaneBasis), cand.params = 3; break;
    case RoofType::kGable: fit = FitLinearRoof(pts, rect, 2, &GableBasis), cand.params = 2; break;
    case RoofType::kHip: fit = FitLinearRoof(pts, rect, 2, &HipBasis), cand.params = 2; break;
    case RoofType::kDome: return absl::InvalidArgumentError("a dome is fitted as a spheroid, not on a rectangle");
  }
  if (!fit.ok()) return fit.status();
  cand.fit = *std::move(fit);
  return cand;
}

// Rectangle candidates for a roof type: a gable's ridge may run along either axis.
std::vector<Rect2> RectsFor(RoofType roof, const Rect2& rect) {
  if (roof == RoofType::kGable) return {rect, Turned(rect)};
  if (roof == RoofType::kHip && rect.half.y() > rect.half.x()) return {Turned(rect)};
  return {rect};
}

BuildingPrimitive ToPrimitive(const Candidate& c, double base_z) {
  BuildingPrimitive p;
  switch (c.roof) {
    case RoofType::kShed: p = ShedFromPlane(c.rect, c.fit.coef); break;
    case RoofType::kGable:
      p = PrimitiveFromRect(c.rect, PrimitiveType::kWedge, RoofType::kGable);
      p.eave_height_m = c.fit.coef(0);
      p.roof_height_m = c.fit.coef(1);
      break;
    case RoofType::kHip:
      p = PrimitiveFromRect(c.rect, PrimitiveType::kPolyhedron, RoofType::kHip);
      p.eave_height_m = c.fit.coef(0);
      p.roof_height_m = c.fit.coef(1);
      p.polygon_m = RectCorners(c.rect);
      break;
    default:
      p = PrimitiveFromRect(c.rect, PrimitiveType::kBox, RoofType::kFlat);
      p.eave_height_m = c.fit.coef(0);
      break;
  }
  p.base_z_m = base_z;
  p.eave_height_m -= base_z;
  p.rms_m = c.fit.rms_m;
  p.point_count = static_cast<uint32_t>(c.fit.inliers);
  return p;
}

absl::StatusOr<BuildingPrimitive> DomePart(const std::vector<Vector3d>& pts, double base_z, PrimitiveType type) {
  absl::StatusOr<SpheroidFit> s = FitSpheroid(pts);
  if (!s.ok()) return s.status();
  BuildingPrimitive p;
  p.type = type;
  p.roof = RoofType::kDome;
  p.center_m = s->center;
  p.size_m = Vector2d::Constant(2 * s->radius_m);
  p.base_z_m = base_z;
  p.eave_height_m = s->z0_m - base_z;
  p.roof_height_m = s->rise_m;
  p.rms_m = s->rms_m;
  p.point_count = static_cast<uint32_t>(s->inliers);
  return p;
}

// Picks among candidate roofs: lowest rms plus a small charge per extra height parameter, so a
// flat roof is not read as a 1-cm shed; a pitched roof with under 0.3 m rise is read as flat.
const Candidate* Best(const std::vector<Candidate>& cands) {
  const Candidate* best = nullptr;
  double best_score = 0;
  for (const Candidate& c : cands) {
    if (c.roof == RoofType::kGable || c.roof == RoofType::kHip)
      if (c.fit.coef(1) < 0.3) continue;
    if (c.roof == RoofType::kShed && 2 * c.fit.coef.tail<2>().norm() * std::max(c.rect.half.x(), c.rect.half.y()) < 0.3)
      continue;
    const double score = c.fit.rms_m + 0.03 * (c.params - 1);
    if (!best || score < best_score) best = &c, best_score = score;
  }
  return best;
}

// Re-centres the rectangle on the middle of its roof points' extent along each axis: the cells a
// regular scan pattern reaches are shifted by up to half a cell when its rows line up with the
// grid, the points themselves are not.
void CenterOnPoints(const std::vector<Vector3d>& pts, Rect2& rect) {
  if (pts.size() < 20) return;
  std::vector<double> u, v;
  for (const auto& p : pts) {
    const Vector2d uv = rect.ToPart(p.head<2>());
    u.push_back(uv.x()), v.push_back(uv.y());
  }
  const size_t k = pts.size() / 500;
  std::nth_element(u.begin(), u.begin() + k, u.end());
  const double u0 = u[k];
  std::nth_element(u.begin(), u.end() - 1 - k, u.end());
  const double u1 = u[u.size() - 1 - k];
  std::nth_element(v.begin(), v.begin() + k, v.end());
  const double v0 = v[k];
  std::nth_element(v.begin(), v.end() - 1 - k, v.end());
  const double v1 = v[v.size() - 1 - k];
  const double c = std::cos(rect.yaw_rad), s = std::sin(rect.yaw_rad);
  const Vector2d shift(0.5 * (u0 + u1), 0.5 * (v0 + v1));
  if (shift.norm() > 0.5 * std::min(rect.half.x(), rect.half.y())) return;  // points off the footprint: keep the cells' centre
  rect.center += Vector2d(c * shift.x() - s * shift.y(), s * shift.x() + c * shift.y());
}

// Sizes a rectangular part from its roof points rather than its cells (which cells count as
// building depends on the ground filter's verdict on mixed edge cells): the points at or above the
// eaves span the roof to within about one point spacing, which the point density gives.
void RefineExtentOnRoofPoints(const std::vector<Vector3d>& pts, BuildingPrimitive& p) {
  const Rect2 rect{p.center_m, 0.5 * p.size_m, p.yaw_rad};
  const double eave_z = p.base_z_m + p.eave_height_m;
  std::vector<double> u, v;
  for (const auto& q : pts) {
    const Vector2d uv = rect.ToPart(q.head<2>());
    if (q.z() < eave_z - 0.3 || std::abs(uv.x()) > rect.half.x() + 1 || std::abs(uv.y()) > rect.half.y() + 1) continue;
    u.push_back(uv.x()), v.push_back(uv.y());
  }
  if (u.size() < 50) return;
  const size_t k = u.size() / 500;
  std::sort(u.begin(), u.end());
  std::sort(v.begin(), v.end());
  const double u0 = u[k], u1 = u[u.size() - 1 - k], v0 = v[k], v1 = v[v.size() - 1 - k];
  // The outermost points lie up to one point spacing inside each wall; the spacing from the point
  // density. Adding half of it on each axis (not the whole: regular scan rows often line up with
  // walls) gave the smallest size error on the campus survey (ave_buildings_test prints it).
  const double spacing = std::sqrt((u1 - u0) * (v1 - v0) / static_cast<double>(u.size()));
  const Vector2d size(u1 - u0 + 0.5 * spacing, v1 - v0 + 0.5 * spacing);
  if (!size.allFinite() || (size - p.size_m).cwiseAbs().maxCoeff() > 2.0) return;  // implausible: keep the cells' size
  const double c = std::cos(p.yaw_rad), s = std::sin(p.yaw_rad);
  const Vector2d shift(0.5 * (u0 + u1), 0.5 * (v0 + v1));
  p.center_m += Vector2d(c * shift.x() - s * shift.y(), s * shift.x() + c * shift.y());
  p.size_m = size;
  if (!p.polygon_m.empty()) p.polygon_m = RectCorners(Rect2{p.center_m, 0.5 * p.size_m, p.yaw_rad});
}

}  // namespace

Vector2d Rect2::ToPart(const Vector2d& p) const {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  const Vector2d d = p - center;
  return Vector2d(c * d.x() + s * d.y(), -s * d.x() + c * d.y());
}

absl::StatusOr<FootprintShape> ShapeOfCells(const std::vector<Vector2d>& cell_centers, double resolution_m) {
  if (cell_centers.size() < 3)
    return absl::InvalidArgumentError(absl::StrFormat("footprint has %d cells; need at least 3", cell_centers.size()));
  // Relative to the first centre so float keeps millimetres far from the origin.
  const Vector2d ref = cell_centers.front();
  std::vector<cv::Point2f> pts;
  pts.reserve(cell_centers.size());
  for (const auto& c : cell_centers) pts.emplace_back(static_cast<float>(c.x() - ref.x()), static_cast<float>(c.y() - ref.y()));
  const cv::RotatedRect rr = cv::minAreaRect(pts);
  FootprintShape shape;
  // Cell centres sit half a cell inside the cells' outline, but the outermost cells are those any
  // roof point reached, which overshoot the wall by half a cell on average: the centre-to-centre
  // extent is the unbiased size (campus at 0.5 m: mean size error 0.5 m -> see docs/BENCHMARKS.md).
  const double w = rr.size.width, h = rr.size.height;
  if (rr.size.width < 0.5 * resolution_m || rr.size.height < 0.5 * resolution_m)
    return absl::InvalidArgumentError("footprint cells are collinear: no area to fit a primitive to");
  shape.rect.center = ref + Vector2d(rr.center.x, rr.center.y);
  shape.rect.half = Vector2d(0.5 * w, 0.5 * h);
  shape.rect.yaw_rad = rr.angle * std::numbers::pi / 180;
  shape.fill = cell_centers.size() * resolution_m * resolution_m / ((w + resolution_m) * (h + resolution_m));
  // A rectangle fills ~1, an ellipse pi/4 ~ 0.785 of its bounding rectangle; at coarse cells a
  // turned rectangle's fill drops too, so round also needs (almost) no cells outside the
  // rectangle's inscribed ellipse (a rectangle has a fifth of its area in the corners).
  int outside = 0;
  const Vector2d ellipse = shape.rect.half + Vector2d::Constant(0.5 * resolution_m);
  for (const auto& c : cell_centers) {
    const Vector2d uv = shape.rect.ToPart(c);
    outside += (uv.x() / ellipse.x()) * (uv.x() / ellipse.x()) + (uv.y() / ellipse.y()) * (uv.y() / ellipse.y()) > 1.0;
  }
  shape.round = shape.fill < 0.92 && shape.fill > 0.6 && outside < 0.08 * static_cast<double>(cell_centers.size());
  return shape;
}

absl::StatusOr<LinearFit> FitLinearRoof(const std::vector<Vector3d>& points, const Rect2& rect, int columns, BasisFn basis,
                                        int rounds) {
  std::vector<char> use(points.size(), 1);
  LinearFit out;
  for (int round = 0; round <= rounds; ++round) {
    const int n = static_cast<int>(std::count(use.begin(), use.end(), 1));
    if (n < std::max(kMinPoints, columns + 2))
      return absl::FailedPreconditionError(absl::StrFormat("%d roof points; need at least %d", n, std::max(kMinPoints, columns + 2)));
    Eigen::MatrixXd a(n, columns);
    Eigen::VectorXd z(n);
    // Heights relative to the first point keep the solve well scaled at any origin.
    const double z_ref = points.front().z();
    Eigen::VectorXd row(columns);
    for (size_t i = 0, r = 0; i < points.size(); ++i) {
      if (!use[i]) continue;
      basis(rect, rect.ToPart(points[i].head<2>()), row);
      a.row(r) = row.transpose();
      z(r++) = points[i].z() - z_ref;
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
    qr.setThreshold(1e-9);
    if (qr.rank() < columns)
      return absl::FailedPreconditionError(
          absl::StrFormat("degenerate roof points (design rank %d of %d): collinear or coincident", qr.rank(), columns));
    out.coef = qr.solve(z);
    if (!out.coef.allFinite()) return absl::FailedPreconditionError("roof fit is not finite");
    out.coef(0) += z_ref;
    const Eigen::VectorXd res = a * out.coef - (z.array() + z_ref).matrix();
    out.rms_m = std::sqrt(res.squaredNorm() / n);
    out.inliers = n;
    if (round == rounds) break;
    const double gate = std::max(0.25, 2.5 * out.rms_m);
    for (size_t i = 0; i < points.size(); ++i) {
      basis(rect, rect.ToPart(points[i].head<2>()), row);
      use[i] = std::abs(row.dot(out.coef) - points[i].z()) <= gate;
    }
  }
  return out;
}

absl::StatusOr<SpheroidFit> FitSpheroid(const std::vector<Vector3d>& points) {
  if (points.size() < 8) return absl::FailedPreconditionError(absl::StrFormat("%d dome points; need at least 8", points.size()));
  Vector3d mean = Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  std::vector<char> use(points.size(), 1);
  SpheroidFit out;
  for (int round = 0; round < 3; ++round) {
    const int n = static_cast<int>(std::count(use.begin(), use.end(), 1));
    if (n < 8) return absl::FailedPreconditionError(absl::StrFormat("%d dome points left after trimming; need 8", n));
    // x^2 + y^2 = 2a x + 2b y - k z^2 + 2 k z0 z + c, relative to the centroid.
    Eigen::MatrixXd a(n, 5);
    Eigen::VectorXd rhs(n);
    for (size_t i = 0, r = 0; i < points.size(); ++i) {
      if (!use[i]) continue;
      const Vector3d q = points[i] - mean;
      a.row(r) << q.x(), q.y(), -q.z() * q.z(), q.z(), 1;
      rhs(r++) = q.x() * q.x() + q.y() * q.y();
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
    qr.setThreshold(1e-9);
    if (qr.rank() < 5)
      return absl::FailedPreconditionError(absl::StrFormat("degenerate dome points (design rank %d of 5)", qr.rank()));
    const Eigen::VectorXd c = qr.solve(rhs);
    const double k = c(2);
    if (!(k > 1e-3 && k < 1e3)) return absl::FailedPreconditionError(absl::StrFormat("points do not curve like a dome (k = %g)", k));
    const double ca = 0.5 * c(0), cb = 0.5 * c(1), z0 = c(3) / (2 * k);
    const double r2 = c(4) + ca * ca + cb * cb + k * z0 * z0;
    if (!(r2 > 0) || !std::isfinite(r2)) return absl::FailedPreconditionError("dome fit has no real radius");
    out.center = mean.head<2>() + Vector2d(ca, cb);
    out.radius_m = std::sqrt(r2);
    out.z0_m = mean.z() + z0;
    out.rise_m = out.radius_m / std::sqrt(k);
    double sum = 0;
    int inside = 0;
    std::vector<double> res(points.size(), 1e9);
    for (size_t i = 0; i < points.size(); ++i) {
      const double rho2 = (points[i].head<2>() - out.center).squaredNorm() / r2;
      if (rho2 >= 1) continue;
      res[i] = points[i].z() - (out.z0_m + out.rise_m * std::sqrt(1 - rho2));
      if (use[i]) sum += res[i] * res[i], ++inside;
    }
    if (inside < 8) return absl::FailedPreconditionError("too few points inside the fitted dome");
    out.rms_m = std::sqrt(sum / inside);
    const double gate = std::max(0.3, 2.5 * out.rms_m);
    for (size_t i = 0; i < points.size(); ++i) use[i] = std::abs(res[i]) <= gate;
    out.inliers = static_cast<int>(std::count(use.begin(), use.end(), 1));
  }
  return out;
}

absl::StatusOr<BuildingPrimitive> FitPart(const std::vector<Vector3d>& roof_points, const std::vector<Vector2d>& cell_centers,
                                          double resolution_m, double base_z_m, const PartRequest& request,
                                          const std::vector<Vector3d>* extent_points) {
  absl::StatusOr<FootprintShape> shape = ShapeOfCells(cell_centers, resolution_m);
  if (!shape.ok()) return shape.status();
  CenterOnPoints(roof_points, shape->rect);
  const PrimitiveType type =
      request.type.value_or(shape->round ? PrimitiveType::kCylinder : PrimitiveType::kBox);
  if (type == PrimitiveType::kSphere) return DomePart(roof_points, base_z_m, PrimitiveType::kSphere);

  std::vector<RoofType> roofs;
  if (request.roof) {
    roofs = {*request.roof};
  } else if (!request.type) {
    roofs = shape->round ? std::vector<RoofType>{RoofType::kCylinder, RoofType::kDome}
                         : std::vector<RoofType>{RoofType::kFlat, RoofType::kShed, RoofType::kGable, RoofType::kHip};
  } else {
    switch (type) {
      case PrimitiveType::kBox: roofs = {RoofType::kFlat}; break;
      case PrimitiveType::kWedge: roofs = {RoofType::kShed, RoofType::kGable}; break;
      case PrimitiveType::kCylinder: roofs = {RoofType::kCylinder}; break;
      default: roofs = {RoofType::kFlat, RoofType::kShed, RoofType::kGable, RoofType::kHip}; break;
    }
  }
  std::vector<Candidate> cands;
  absl::Status last = absl::OkStatus();
  std::optional<BuildingPrimitive> dome;
  for (RoofType roof : roofs) {
    if (roof == RoofType::kDome) {
      absl::StatusOr<BuildingPrimitive> d = DomePart(roof_points, base_z_m, PrimitiveType::kSphere);
      if (d.ok()) dome = *d;
      else last = d.status();
      continue;
    }
    for (const Rect2& r : RectsFor(roof, shape->rect)) {
      absl::StatusOr<Candidate> c = FitCandidate(roof_points, r, roof);
      if (c.ok()) cands.push_back(*std::move(c));
      else last = c.status();
    }
  }
  const Candidate* best = Best(cands);
  if (!best && request.roof && !cands.empty()) best = &cands.front();  // asked for: report it even if nearly flat
  if (dome && (!best || dome->rms_m + 0.05 < best->fit.rms_m)) return *dome;
  if (!best) return last.ok() ? absl::FailedPreconditionError("no roof model fits these points") : last;
  BuildingPrimitive p = ToPrimitive(*best, base_z_m);
  RefineExtentOnRoofPoints(extent_points ? *extent_points : roof_points, p);
  if (shape->round || type == PrimitiveType::kCylinder) {
    p.type = PrimitiveType::kCylinder;
    p.roof = RoofType::kCylinder;
  }
  if (type == PrimitiveType::kPolyhedron) {
    p.type = PrimitiveType::kPolyhedron;
    if (p.polygon_m.empty()) p.polygon_m = RectCorners(best->rect);
  }
  return p;
}

std::optional<double> PrimitiveRoofAt(const BuildingPrimitive& part, double x, double y) {
  Rect2 r{part.center_m, 0.5 * part.size_m, part.yaw_rad};
  const Vector2d uv = r.ToPart(Vector2d(x, y));
  const double hx = r.half.x(), hy = r.half.y();
  const bool round = part.roof == RoofType::kDome || part.roof == RoofType::kCylinder;
  const double rho2 = (uv.x() / hx) * (uv.x() / hx) + (uv.y() / hy) * (uv.y() / hy);
  if (round ? rho2 > 1 : (std::abs(uv.x()) > hx || std::abs(uv.y()) > hy)) return std::nullopt;
  double z = part.base_z_m + part.eave_height_m;
  const double rise = part.roof_height_m;
  switch (part.roof) {
    case RoofType::kFlat:
    case RoofType::kCylinder: break;
    case RoofType::kGable: z += rise * (1 - std::abs(uv.y()) / hy); break;
    case RoofType::kShed: z += rise * (uv.y() + hy) / (2 * hy); break;
    case RoofType::kHip: {
      const double hs = std::min(hx, hy);
      z += rise * std::min((hx - std::abs(uv.x())) / hs, (hy - std::abs(uv.y())) / hs);
      break;
    }
    case RoofType::kDome: z += rise * std::sqrt(std::max(0.0, 1 - rho2)); break;
  }
  return z;
}

}  // namespace ave::model::internal
