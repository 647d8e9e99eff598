#include "tests/truth/survey_truth.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>

#include "absl/strings/str_format.h"
#include "model_store/terrain/terrain.h"
#include "sensor_agent/sim/airborne_lidar.h"

namespace ave::model::testing {

using Eigen::Vector2d;
using Eigen::Vector3d;

HeightGrid GridWithTruthGround(const PointCloud& cloud, const scene::SyntheticCampus& site, double resolution_m) {
  absl::StatusOr<HeightGrid> built = BuildHeightGrid(cloud, resolution_m);
  if (!built.ok()) return HeightGrid{};
  HeightGrid g = *std::move(built);
  const size_t n = g.CellCount();
  const double dz = site.origin.z() - cloud.origin.z();
  const Vector2d dxy = (site.origin - cloud.origin).head<2>();
  g.cell_class.assign(n, CellClass::kEmpty);
  g.dtm.assign(n, 0);
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) {
      const size_t i = g.Index(c, r);
      const Vector2d q = g.CellCenter(c, r) - dxy;  // site frame
      g.dtm[i] = static_cast<float>(site.TerrainHeight(q.x(), q.y()) + dz);
      if (!g.count[i]) continue;
      g.cell_class[i] = g.zmax[i] - g.dtm[i] < 0.5 ? CellClass::kGround : CellClass::kObject;
    }
  return g;
}

absl::Status WriteSurveyLas(const scene::SyntheticCampus& site, double spacing_m, uint64_t seed, const std::string& path) {
  sim::AirborneLidarSpec spec;
  spec.point_spacing_m = spacing_m;
  return sim::SimulateAirborneLidar(site, spec, sim::EffectSet{}, seed, path);
}

absl::StatusOr<Survey> SurveySite(const scene::SyntheticCampus& site, double spacing_m, double resolution_m, uint64_t seed) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            absl::StrFormat("ave_buildings_%d_%d.las", static_cast<int>(::getpid()), static_cast<int>(seed)))
                               .string();
  if (absl::Status s = WriteSurveyLas(site, spacing_m, seed, path); !s.ok()) return s;
  absl::StatusOr<sim::LasFile> las = sim::ReadLas6(path);
  std::filesystem::remove(path);
  if (!las.ok()) return las.status();
  Survey out;
  out.cloud.origin = site.origin;
  for (const auto& p : las->points) {
    out.cloud.xyz.push_back((p.p_world - site.origin).cast<float>());
    out.cloud.intensity.push_back(p.intensity);
    out.cloud.classification.push_back(p.classification);
    out.cloud.point_source_id.push_back(p.point_source_id);
  }
  out.grid = GridWithTruthGround(out.cloud, site, resolution_m);
  return out;
}

RoofType TruthRoof(scene::PrimitiveKind kind) {
  switch (kind) {
    case scene::PrimitiveKind::kBox: return RoofType::kFlat;
    case scene::PrimitiveKind::kGable: return RoofType::kGable;
    case scene::PrimitiveKind::kShed: return RoofType::kShed;
    case scene::PrimitiveKind::kHip: return RoofType::kHip;
    case scene::PrimitiveKind::kCylinder: return RoofType::kCylinder;
    case scene::PrimitiveKind::kDome: return RoofType::kDome;
  }
  return RoofType::kFlat;
}

namespace {

double AngleDiffDeg(double a_rad, double b_rad, double period_rad) {
  const double d = std::remainder(a_rad - b_rad, period_rad);
  return std::abs(d) * 180 / std::numbers::pi;
}

void Accumulate(double v, double& sum, double& max) {
  sum += v;
  max = std::max(max, v);
}

}  // namespace

BuildingScore ScoreBuildings(const scene::SyntheticCampus& site, const Vector3d& cloud_origin,
                             const std::vector<BuildingRecord>& detected) {
  BuildingScore s;
  s.truth = static_cast<int>(site.buildings.size());
  s.detected = static_cast<int>(detected.size());
  const Vector2d to_site = (cloud_origin - site.origin).head<2>();
  const double dz = cloud_origin.z() - site.origin.z();
  std::vector<int> best(site.buildings.size(), -1);
  std::vector<int> hits(site.buildings.size(), 0);
  for (size_t d = 0; d < detected.size(); ++d) {
    const Vector2d c = detected[d].parts.front().center_m + to_site;
    const int b = site.BuildingAt(c.x(), c.y());
    if (b < 0) {
      s.mistakes.push_back(absl::StrFormat("false building at (%.1f, %.1f), %.0f m2", c.x(), c.y(), detected[d].area_m2));
      continue;
    }
    ++s.true_positive_detections;
    if (hits[b]++ > 0) ++s.split;
    if (best[b] < 0 || detected[d].area_m2 > detected[best[b]].area_m2) best[b] = static_cast<int>(d);
  }
  for (size_t b = 0; b < site.buildings.size(); ++b) {
    const scene::BoxBuilding& t = site.buildings[b];
    if (best[b] < 0) {
      s.mistakes.push_back("missed " + t.id);
      continue;
    }
    ++s.found;
    const BuildingPrimitive& p = detected[best[b]].parts.front();
    const RoofType want = TruthRoof(t.kind);
    if (p.roof == want) ++s.roof_correct;
    else s.mistakes.push_back(absl::StrFormat("%s: roof %s, truth %s", t.id, RoofTypeName(p.roof), RoofTypeName(want)));
    Accumulate((p.center_m + to_site - t.center_m).norm(), s.center_err_m_mean, s.center_err_m_max);
    s.center_bias_m += p.center_m + to_site - t.center_m;
    Vector2d a = p.size_m, w = t.size_m;
    if (a.x() > a.y()) std::swap(a.x(), a.y());
    if (w.x() > w.y()) std::swap(w.x(), w.y());
    const double size_err = std::max(std::abs(a.x() - w.x()), std::abs(a.y() - w.y()));
    Accumulate(size_err, s.size_err_m_mean, s.size_err_m_max);
    if (size_err > 0.5)
      s.mistakes.push_back(absl::StrFormat("%s: size %.2f x %.2f m, truth %.2f x %.2f m", t.id, a.x(), a.y(), w.x(), w.y()));
    const double ground = site.BuildingGround(t);
    Accumulate(std::abs(p.base_z_m + dz + p.eave_height_m - (ground + t.height_m)), s.eave_err_m_mean, s.eave_err_m_max);
    Accumulate(std::abs(p.roof_height_m - t.roof_height_m), s.roof_height_err_m_mean, s.roof_height_err_m_max);
    const bool round = want == RoofType::kDome || want == RoofType::kCylinder;
    if (!round) {
      const bool fourfold = want == RoofType::kFlat || (want == RoofType::kHip);
      Accumulate(AngleDiffDeg(p.yaw_rad, t.yaw_rad, fourfold ? std::numbers::pi / 2 : std::numbers::pi), s.yaw_err_deg_mean,
                 s.yaw_err_deg_max);
    }
  }
  if (s.found > 0) {
    s.center_err_m_mean /= s.found, s.size_err_m_mean /= s.found, s.eave_err_m_mean /= s.found;
    s.roof_height_err_m_mean /= s.found, s.yaw_err_deg_mean /= s.found;
    s.center_bias_m /= s.found;
  }
  s.precision = s.detected ? static_cast<double>(s.true_positive_detections) / s.detected : 1.0;
  s.recall = s.truth ? static_cast<double>(s.found) / s.truth : 1.0;
  s.roof_accuracy = s.found ? static_cast<double>(s.roof_correct) / s.found : 0.0;
  return s;
}

}  // namespace ave::model::testing
