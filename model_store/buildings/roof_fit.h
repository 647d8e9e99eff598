#pragma once
// Least-squares roof and primitive fits behind buildings.h (AVE §4.1, after You, Hu, Neumann & Fox
// 2003): every model is linear in its heights once the footprint frame is known, so each fit is one
// small QR solve with trimmed re-fits against wall and overhang points. Internal to
// model_store/buildings; exposed for its tests.
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include "absl/status/statusor.h"

#include "model_store/buildings/buildings.h"

namespace ave::model::internal {

// An oriented rectangle in the local frame (x east, y north): centre, half sizes along its own
// axes, and its x axis at yaw_rad from east.
struct Rect2 {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  Eigen::Vector2d half = Eigen::Vector2d::Ones();
  double yaw_rad = 0;
  Eigen::Vector2d ToPart(const Eigen::Vector2d& p) const;
};

// Footprint shape of a part from the centres of its cells (cell size `resolution_m`): the
// minimum-area rectangle, and whether the cells look round (fill ratio of the rectangle near pi/4).
struct FootprintShape {
  Rect2 rect;
  double fill = 1;
  bool round = false;
};
absl::StatusOr<FootprintShape> ShapeOfCells(const std::vector<Eigen::Vector2d>& cell_centers, double resolution_m);

// Linear least squares z ~ basis(x, y) . c with `rounds` trimmed refits (points beyond
// max(0.25 m, 2.5 rms) dropped). Fails, with the reason, on too few points or a rank-deficient
// design (collinear or coincident points): never returns NaN.
struct LinearFit {
  Eigen::VectorXd coef;
  double rms_m = 0;
  int inliers = 0;
};
using BasisFn = void (*)(const Rect2& rect, const Eigen::Vector2d& uv, Eigen::Ref<Eigen::VectorXd> row);
absl::StatusOr<LinearFit> FitLinearRoof(const std::vector<Eigen::Vector3d>& points, const Rect2& rect, int columns,
                                        BasisFn basis, int rounds = 3);

// Spheroid of revolution (x-a)^2 + (y-b)^2 + k (z-z0)^2 = R^2 fitted algebraically (linear in
// a, b, k, k z0, const) to the upper-half points: a dome or sphere primitive.
struct SpheroidFit {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius_m = 0;   // horizontal
  double z0_m = 0;       // equator (eaves for a dome)
  double rise_m = 0;     // vertical semi-axis
  double rms_m = 0;      // vertical residual over the points inside the radius
  int inliers = 0;       // points within the final trimming gate
};
absl::StatusOr<SpheroidFit> FitSpheroid(const std::vector<Eigen::Vector3d>& points);

// Fits one part of the requested kind (nullopt: choose the roof type automatically) to its roof
// points and footprint cells. base_z_m: ground under the building (local height).
struct PartRequest {
  std::optional<PrimitiveType> type;
  std::optional<RoofType> roof;
};
// `extent_points` (optional): points around the part, its cells and a margin of a few cells, from
// which a rectangular part's size is measured (those at or above its eaves); default roof_points.
absl::StatusOr<BuildingPrimitive> FitPart(const std::vector<Eigen::Vector3d>& roof_points,
                                          const std::vector<Eigen::Vector2d>& cell_centers, double resolution_m,
                                          double base_z_m, const PartRequest& request,
                                          const std::vector<Eigen::Vector3d>* extent_points = nullptr);

// The analytic roof height of a fitted primitive at local (x, y), or nullopt outside it.
std::optional<double> PrimitiveRoofAt(const BuildingPrimitive& part, double x, double y);

}  // namespace ave::model::internal
