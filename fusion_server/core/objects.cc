#include "fusion_server/core/objects.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace ave {

std::string ObjectOptions::Check() const {
  if (!(gate_m > 0 && std::isfinite(gate_m))) return "gate_m must be finite and > 0";
  if (!(gate_sigma > 0 && std::isfinite(gate_sigma))) return "gate_sigma must be finite and > 0";
  if (!(forget_s > 0 && std::isfinite(forget_s))) return "forget_s must be finite and > 0";
  if (!(process_speed_mps >= 0 && std::isfinite(process_speed_mps))) return "process_speed_mps must be >= 0";
  if (max_path < 2) return "max_path must be >= 2";
  if (!(path_step_m >= 0 && heading_step_m > 0)) return "path_step_m must be >= 0 and heading_step_m > 0";
  return "";
}

ObjectFusion::ObjectFusion(ObjectOptions options) : options_(options) {
  if (std::string why = options.Check(); !why.empty()) throw std::invalid_argument("ObjectOptions: " + why);
}

bool ObjectFusion::Within(const FusedObject& object, const Eigen::Vector3d& p, const Eigen::Matrix2d& cov) const {
  const Eigen::Vector2d d = (p - object.position).head<2>();
  if (!(d.norm() <= options_.gate_m)) return false;
  const Eigen::Matrix2d s = object.covariance_xy + cov;
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(s);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return true;  // metric gate only
  return d.dot(ldlt.solve(d)) <= options_.gate_sigma * options_.gate_sigma;
}

void ObjectFusion::Update(FusedObject& o, const ObjectObservation& obs) {
  const Placement& z = obs.placement;
  const double dt = std::max(0.0, (obs.t_ns - o.last_seen_ns) * 1e-9);
  // Predict: random walk in the ground plane.
  Eigen::Matrix2d p = o.covariance_xy;
  p.diagonal().array() += options_.process_speed_mps * options_.process_speed_mps * dt;
  // Update (Joseph form), height taken from the newest contact (the terrain under it).
  const Eigen::Matrix2d s = p + z.covariance_xy;
  const Eigen::Matrix2d gain = s.ldlt().solve(p.transpose()).transpose();  // P S^-1 (S, P symmetric)
  const Eigen::Vector2d innovation = (z.position - o.position).head<2>();
  if (gain.allFinite()) {
    o.position.head<2>() += gain * innovation;
    const Eigen::Matrix2d ikh = Eigen::Matrix2d::Identity() - gain;
    o.covariance_xy = ikh * p * ikh.transpose() + gain * z.covariance_xy * gain.transpose();
    o.covariance_xy = 0.5 * (o.covariance_xy + o.covariance_xy.transpose()).eval();
    o.covariance_xy.diagonal() = o.covariance_xy.diagonal().cwiseMax(1e-4);
  }
  o.position.z() = z.position.z();
  if (obs.size_measured) {
    o.size_m = o.size_m.isZero() || !o.size_measured ? z.size_m : (0.8 * o.size_m + 0.2 * z.size_m).eval();
    o.size_measured = true;
  } else if (o.size_m.isZero()) {
    o.size_m = z.size_m;
  }
  ++o.kind_votes[static_cast<int>(z.kind)];
  // A known kind wins a tie with "unknown" (a LiDAR's person track against a camera's box too
  // small or cut to say what it is); between known kinds the first, as before.
  int best = static_cast<int>(std::max_element(o.kind_votes + 1, o.kind_votes + 3) - o.kind_votes);
  if (o.kind_votes[0] > o.kind_votes[best]) best = 0;
  o.kind = static_cast<ObjectKind>(best);
  o.shape = o.kind == ObjectKind::kCar ? ObjectShape::kCuboid : ObjectShape::kBillboard;
  if (o.kind == ObjectKind::kCar && o.size_m.y() < o.size_m.x()) std::swap(o.size_m.x(), o.size_m.y());
  const Eigen::Vector2d moved = (o.position - o.heading_anchor).head<2>();
  if (moved.norm() >= options_.heading_step_m) {
    o.heading_rad = std::atan2(moved.y(), moved.x());
    o.heading_anchor = o.position;
  }
  if (o.path.empty() || (o.position - o.path.back()).head<2>().norm() >= options_.path_step_m) {
    o.path.push_back(o.position);
    while (o.path.size() > options_.max_path) o.path.pop_front();
  }
  o.cameras[obs.camera_id] = {obs.track_id, obs.t_ns};
  o.newest_camera = obs.camera_id;
  o.last_seen_ns = std::max(o.last_seen_ns, obs.t_ns);
}

void ObjectFusion::Retie(const std::string& camera, uint64_t from, uint64_t to) {
  for (auto it = ties_.lower_bound({camera, 0, 0}); it != ties_.end() && std::get<0>(it->first) == camera;) {
    if (it->second != from) {
      ++it;
    } else if (to != 0) {
      (it++)->second = to;
    } else {
      it = ties_.erase(it);
    }
  }
}

uint64_t ObjectFusion::Observe(const ObjectObservation& obs) {
  const Placement& z = obs.placement;
  if (!z.position.allFinite() || !z.covariance_xy.allFinite()) return 0;
  // The object this camera's track (of this stream session) is already tied to.
  const TrackKey key{obs.camera_id, obs.session, obs.track_id};
  if (auto tie = ties_.find(key); tie != ties_.end()) {
    auto it = objects_.find(tie->second);
    if (it != objects_.end()) {
      Update(it->second, obs);
      return it->first;
    }
    ties_.erase(tie);
  }
  // A new track: the nearest live object within the gate that this camera does not already hold.
  FusedObject* best = nullptr;
  double best_d = std::numeric_limits<double>::infinity();
  const int64_t forget_ns = static_cast<int64_t>(options_.forget_s * 1e9);
  for (auto& [id, o] : objects_) {
    auto it = o.cameras.find(obs.camera_id);
    if (it != o.cameras.end() && obs.t_ns - it->second.second < forget_ns) continue;
    if (!Within(o, z.position, z.covariance_xy)) continue;
    const double d = (z.position - o.position).head<2>().norm();
    if (d < best_d) best_d = d, best = &o;
  }
  if (best) {
    best->cameras.erase(obs.camera_id);
    Retie(obs.camera_id, best->id, 0);
    Update(*best, obs);
    ties_[key] = best->id;
    return best->id;
  }
  FusedObject o;
  o.id = next_id_++;
  o.position = z.position;
  o.covariance_xy = z.covariance_xy;
  o.size_m = z.size_m;
  o.size_measured = obs.size_measured;
  o.kind = z.kind;
  o.shape = z.shape;
  o.first_seen_ns = o.last_seen_ns = obs.t_ns;
  o.heading_anchor = z.position;
  o.path.push_back(z.position);
  o.cameras[obs.camera_id] = {obs.track_id, obs.t_ns};
  o.newest_camera = obs.camera_id;
  ++o.kind_votes[static_cast<int>(z.kind)];
  const uint64_t id = o.id;
  objects_.emplace(id, std::move(o));
  ties_[key] = id;
  return id;
}

void ObjectFusion::Expire(int64_t now_ns) {
  const int64_t forget_ns = static_cast<int64_t>(options_.forget_s * 1e9);
  for (auto it = objects_.begin(); it != objects_.end();) {
    FusedObject& o = it->second;
    for (auto c = o.cameras.begin(); c != o.cameras.end();) {
      if (now_ns - c->second.second <= forget_ns) {
        ++c;
        continue;
      }
      Retie(c->first, o.id, 0);
      c = o.cameras.erase(c);
    }
    it = o.cameras.empty() ? objects_.erase(it) : std::next(it);
  }
  // Merge objects seen by disjoint cameras that have come within the gate: the older id stays.
  // Candidates are pairs closer than gate_m along the ground axis (x or y) over which the objects
  // spread most (a sweep over the objects sorted along it).
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& [id, o] : objects_) lo = lo.cwiseMin(o.position.head<2>()), hi = hi.cwiseMax(o.position.head<2>());
  const int axis = objects_.empty() || hi.x() - lo.x() >= hi.y() - lo.y() ? 0 : 1;
  std::vector<std::pair<double, uint64_t>> sorted;
  sorted.reserve(objects_.size());
  for (const auto& [id, o] : objects_) sorted.emplace_back(o.position[axis], id);
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::pair<uint64_t, uint64_t>> candidates;  // (older id, newer id)
  for (size_t i = 0; i < sorted.size(); ++i) {
    for (size_t j = i + 1; j < sorted.size() && sorted[j].first - sorted[i].first <= options_.gate_m; ++j) {
      const auto [a, b] = std::minmax(sorted[i].second, sorted[j].second);
      candidates.emplace_back(a, b);
    }
  }
  std::sort(candidates.begin(), candidates.end());
  for (const auto& [keep_id, gone_id] : candidates) {
    auto a = objects_.find(keep_id), b = objects_.find(gone_id);
    if (a == objects_.end() || b == objects_.end()) continue;
    bool shared = false;
    for (const auto& [cam, tie] : b->second.cameras) shared = shared || a->second.cameras.count(cam);
    if (shared || !Within(a->second, b->second.position, b->second.covariance_xy)) continue;
    FusedObject& keep = a->second;
    const FusedObject& gone = b->second;
    const Eigen::Matrix2d s = keep.covariance_xy + gone.covariance_xy;
    const Eigen::Matrix2d gain = s.ldlt().solve(keep.covariance_xy.transpose()).transpose();
    if (gain.allFinite()) {
      keep.position.head<2>() += gain * (gone.position - keep.position).head<2>();
      keep.covariance_xy = (Eigen::Matrix2d::Identity() - gain) * keep.covariance_xy;
      keep.covariance_xy = 0.5 * (keep.covariance_xy + keep.covariance_xy.transpose()).eval();
      keep.covariance_xy.diagonal() = keep.covariance_xy.diagonal().cwiseMax(1e-4);
    }
    if (!keep.size_measured && gone.size_measured) keep.size_m = gone.size_m, keep.size_measured = true;
    for (const auto& c : gone.cameras) {
      keep.cameras.insert(c);
      Retie(c.first, gone.id, keep.id);
    }
    if (gone.last_seen_ns > keep.last_seen_ns) {
      keep.last_seen_ns = gone.last_seen_ns;
      keep.newest_camera = gone.newest_camera;
    }
    objects_.erase(b);
  }
}

uint64_t ObjectFusion::TiedObject(const std::string& camera_id, uint64_t session, uint32_t track_id) const {
  auto it = ties_.find(TrackKey{camera_id, session, track_id});
  return it == ties_.end() || !objects_.count(it->second) ? 0 : it->second;
}

const FusedObject* ObjectFusion::Find(uint64_t id) const {
  auto it = objects_.find(id);
  return it == objects_.end() ? nullptr : &it->second;
}

std::vector<const FusedObject*> ObjectFusion::Live(int64_t now_ns) const {
  std::vector<const FusedObject*> out;
  const int64_t forget_ns = static_cast<int64_t>(options_.forget_s * 1e9);
  for (const auto& [id, o] : objects_) {
    if (now_ns - o.last_seen_ns <= forget_ns) out.push_back(&o);
  }
  return out;
}

}  // namespace ave
