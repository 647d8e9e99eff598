#include "fusion_server/core/placement.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace ave {

TerrainModel::TerrainModel(const TriangleMesh& mesh) {
  TriangleMesh occluders;
  ground_.origin = occluders.origin = mesh.origin;
  ground_.positions = occluders.positions = mesh.positions;
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const SurfaceMaterial m = t < mesh.triangle_material.size() ? mesh.triangle_material[t] : SurfaceMaterial::kTerrain;
    const bool ground = m == SurfaceMaterial::kTerrain || m == SurfaceMaterial::kRoad;
    if (!ground && m != SurfaceMaterial::kWall && m != SurfaceMaterial::kRoof) continue;
    TriangleMesh& into = ground ? ground_ : occluders;
    into.indices.insert(into.indices.end(), mesh.indices.begin() + 3 * t, mesh.indices.begin() + 3 * t + 3);
    into.triangle_material.push_back(m);
  }
  bvh_ = MeshBvh(ground_);
  occluder_bvh_ = MeshBvh(occluders);
}

bool TerrainModel::Occluded(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_m) const {
  return occluder_bvh_.TriangleCount() > 0 && occluder_bvh_.Raycast(origin, direction, 1e-4, max_m).has_value();
}

std::optional<TerrainModel::Hit> TerrainModel::Raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                                       double max_m) const {
  const std::optional<RayHit> hit = bvh_.Raycast(origin, direction, 1e-4, max_m);
  if (!hit) return std::nullopt;
  const Eigen::Vector3d dir = direction.normalized();
  const uint32_t* tri = &ground_.indices[3 * hit->triangle];
  const Eigen::Vector3d a = ground_.positions[tri[0]].cast<double>();
  const Eigen::Vector3d b = ground_.positions[tri[1]].cast<double>();
  const Eigen::Vector3d c = ground_.positions[tri[2]].cast<double>();
  Eigen::Vector3d n = (b - a).cross(c - a);
  if (n.norm() <= 0) return std::nullopt;
  n.normalize();
  if (n.dot(dir) > 0) n = -n;
  return Hit{origin + hit->distance_m * dir, n, hit->distance_m};
}

std::string PlacementOptions::Check() const {
  if (!(max_range_m > 0 && std::isfinite(max_range_m))) return "max_range_m must be finite and > 0";
  if (!(min_grazing_deg >= 0 && min_grazing_deg < 90)) return "min_grazing_deg must be in [0, 90)";
  if (!(pixel_sigma >= 0 && std::isfinite(pixel_sigma))) return "pixel_sigma must be finite and >= 0";
  if (!(default_position_sigma_m >= 0 && std::isfinite(default_position_sigma_m))) return "default_position_sigma_m must be >= 0";
  if (!(default_rotation_sigma_rad >= 0 && std::isfinite(default_rotation_sigma_rad))) {
    return "default_rotation_sigma_rad must be >= 0";
  }
  return "";
}

Eigen::Vector3d UndistortedRay(const PinholeIntrinsics& k, const Eigen::Vector2d& uv) {
  const double xd = (uv.x() - k.cx) / k.fx, yd = (uv.y() - k.cy) / k.fy;
  const auto& d = k.distortion;
  double x = xd, y = yd;
  if (d[0] != 0 || d[1] != 0 || d[2] != 0 || d[3] != 0 || d[4] != 0) {
    // Fixed-point inversion of x_d = x r(x) + t(x) (OpenCV's undistortPoints iteration).
    bool settled = false;
    for (int it = 0; it < 30; ++it) {
      const double r2 = x * x + y * y;
      const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
      const double tx = 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
      const double ty = d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
      if (!(radial > 1e-3) || !std::isfinite(radial)) break;
      const double nx = (xd - tx) / radial, ny = (yd - ty) / radial;
      const double step = std::hypot(nx - x, ny - y);
      x = nx, y = ny;
      if (step < 1e-12) {
        settled = true;
        break;
      }
    }
    if (!settled && !(std::isfinite(x) && std::isfinite(y) && std::hypot(x - xd, y - yd) < 1)) x = xd, y = yd;
  }
  return Eigen::Vector3d(x, y, 1).normalized();
}

namespace {

bool Fail(std::string* why, const char* reason) {
  if (why) *why = reason;
  return false;
}

// A symmetric square root of a covariance (eigenvalues clamped at 0), robust where Cholesky is not.
template <int N>
Eigen::Matrix<double, N, N> SqrtCovariance(const Eigen::Matrix<double, N, N>& cov) {
  const Eigen::Matrix<double, N, N> sym = 0.5 * (cov + cov.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> es(sym);
  return es.eigenvectors() * es.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
}

}  // namespace

std::optional<Placement> PlaceBox(const TerrainModel& terrain, const PinholeIntrinsics& intrinsics,
                                  const Rigid3d& world_from_camera, const Eigen::Matrix<double, 6, 6>* pose_covariance,
                                  const std::array<double, 4>& box, const PlacementOptions& options, std::string* why) {
  const auto [x0, y0, x1, y1] = box;
  if (!(std::isfinite(x0) && std::isfinite(y0) && std::isfinite(x1) && std::isfinite(y1)) || x1 < x0 || y1 < y0) {
    Fail(why, "box is not finite or has negative size");
    return std::nullopt;
  }
  if (!world_from_camera.translation.allFinite() || !world_from_camera.rotation.coeffs().allFinite() ||
      !intrinsics.Check().empty()) {
    Fail(why, "pose or intrinsics not usable");
    return std::nullopt;
  }
  // Ground contact: the bottom-middle of the box, in pixel-centre coordinates.
  const Eigen::Vector2d contact(0.5 * (x0 + x1) - 0.5, y1 - 0.5);
  const Eigen::Vector3d centre = world_from_camera.translation;
  const Eigen::Matrix3d rotation = world_from_camera.rotation.toRotationMatrix();
  const Eigen::Vector3d ray = rotation * UndistortedRay(intrinsics, contact);
  const std::optional<TerrainModel::Hit> hit = terrain.Raycast(centre, ray, options.max_range_m);
  if (!hit) {
    Fail(why, "the ground-contact ray meets no ground within range (sky or off the model)");
    return std::nullopt;
  }
  if (std::fabs(ray.dot(hit->normal)) < std::sin(options.min_grazing_deg * M_PI / 180)) {
    Fail(why, "the ground-contact ray grazes the ground");
    return std::nullopt;
  }
  // From 0.5 m out (a camera on a building's wall or roof does not hide behind its own mount) to
  // 5 cm short of the ground (a wall standing on this very spot does not hide its own foot).
  constexpr double kMountClearance_m = 0.5;
  if (hit->distance_m > kMountClearance_m + 0.05 &&
      terrain.Occluded(centre + kMountClearance_m * ray, ray, hit->distance_m - kMountClearance_m - 0.05)) {
    Fail(why, "the ground-contact ray meets a building before the ground (the box's bottom edge lies on a wall)");
    return std::nullopt;
  }
  // Sigma points over (position, rotation vector, pixel u, v): 2n rays, each re-cast. A perturbed
  // ray that misses the mesh meets the tangent plane at the nominal contact instead.
  constexpr int n = 8;
  Eigen::Matrix<double, n, n> cov = Eigen::Matrix<double, n, n>::Zero();
  if (pose_covariance && pose_covariance->allFinite()) {
    cov.topLeftCorner<6, 6>() = *pose_covariance;
  } else {
    cov.topLeftCorner<3, 3>().diagonal().setConstant(options.default_position_sigma_m * options.default_position_sigma_m);
    cov.block<3, 3>(3, 3).diagonal().setConstant(options.default_rotation_sigma_rad * options.default_rotation_sigma_rad);
  }
  cov(6, 6) = cov(7, 7) = options.pixel_sigma * options.pixel_sigma;
  const Eigen::Matrix<double, n, n> root = SqrtCovariance<n>(cov) * std::sqrt(double(n));
  Eigen::Matrix2d spread = Eigen::Matrix2d::Zero();
  int used = 0;
  for (int i = 0; i < n; ++i) {
    if (root.col(i).squaredNorm() <= 0) continue;
    for (const double sign : {1.0, -1.0}) {
      const Eigen::Matrix<double, n, 1> s = sign * root.col(i);
      const Eigen::Vector3d c = centre + s.head<3>();
      const Eigen::Vector3d rv = s.segment<3>(3);
      const Eigen::Matrix3d r = rv.norm() > 0 ? Eigen::AngleAxisd(rv.norm(), rv.normalized()).toRotationMatrix() * rotation
                                              : rotation;
      const Eigen::Vector3d d = r * UndistortedRay(intrinsics, contact + s.tail<2>());
      Eigen::Vector3d p;
      if (auto h = terrain.Raycast(c, d, 2 * options.max_range_m)) {
        p = h->point;
      } else {
        const double denom = hit->normal.dot(d);
        const double t = std::fabs(denom) > 1e-9 ? hit->normal.dot(hit->point - c) / denom : -1;
        if (!(t > 0 && t < 2 * options.max_range_m)) continue;
        p = c + t * d;
      }
      const Eigen::Vector2d e = (p - hit->point).head<2>();
      spread += e * e.transpose();
      ++used;
    }
  }
  Placement out;
  out.position = hit->point;
  out.range_m = hit->distance_m;
  if (used > 0) out.covariance_xy = spread / used;
  out.covariance_xy = 0.5 * (out.covariance_xy + out.covariance_xy.transpose()).eval();
  // Floors: 1 cm sigma; a sigma point lost to the model's edge makes the estimate less sure.
  out.covariance_xy.diagonal() = out.covariance_xy.diagonal().cwiseMax(1e-4);
  if (used < 2 * n) out.covariance_xy *= double(2 * n) / std::max(used, 1);
  // Size from the box and the contact's depth.
  const double depth = std::max(1e-3, (world_from_camera.Inverse() * hit->point).z());
  const double width = (x1 - x0) * depth / intrinsics.fx, height = (y1 - y0) * depth / intrinsics.fy;
  if (width > 1.6 && width > 0.8 * height) {
    out.kind = ObjectKind::kCar;
    out.shape = ObjectShape::kCuboid;
    out.size_m = Eigen::Vector3d(std::min(width, 2.2), std::max(width, 4.0), height);
  } else {
    out.kind = height >= 0.8 && height <= 2.5 ? ObjectKind::kPerson : ObjectKind::kUnknown;
    out.shape = ObjectShape::kBillboard;
    out.size_m = Eigen::Vector3d(width, width, height);
  }
  if (!out.position.allFinite() || !out.covariance_xy.allFinite()) {
    Fail(why, "placement is not finite");
    return std::nullopt;
  }
  return out;
}

}  // namespace ave
