#pragma once
// The server's moving objects (seed AVE §6.1, issue 6): ground-contact placements from every
// camera, and foot tracks from every rotating LiDAR (i4D §3.2, issue 16: already ground positions
// with a covariance, no ray cast), fused into objects with one stable id each. A "camera" below is
// any sensor. Pure (no gRPC, no locking: SceneState holds
// it under its mutex).
//
// Association: a (camera, stream session, track id) triple once tied to an object stays tied
// while the object lives; the session keeps a restarted agent's track ids (which start at 1 again)
// off the objects of its previous run. A new triple joins the nearest live object that no other
// track of the same camera holds, when its placement lies within the gate (Mahalanobis distance of
// the two uncertainties, and metres); otherwise it starts a new object. Objects from different
// cameras that come within the gate of each other are merged (the older id stays). Each object is a
// constant-position Kalman filter in the ground plane (Joseph-form update, process noise for
// walking/driving speed); heading comes from its motion, its path is the bounded history of fused
// positions.
#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "fusion_server/core/placement.h"

namespace ave {

struct ObjectOptions {
  double gate_m = 2.5;               // association / merge distance cap (metres, ground plane)
  double gate_sigma = 3.5;           // and Mahalanobis cap
  double forget_s = 2.0;             // an object unseen this long is dropped
  double process_speed_mps = 2.0;    // random-walk process noise: variance grows speed^2 * dt
  size_t max_path = 200;             // path points kept
  double path_step_m = 0.25;         // a new path point after moving this far
  double heading_step_m = 0.5;       // heading re-measured after moving this far

  std::string Check() const;
};

struct ObjectObservation {
  std::string camera_id;  // the sensor: a camera, or a rotating LiDAR (issue 16)
  uint32_t track_id = 0;
  int64_t t_ns = 0;  // server clock
  Placement placement;
  uint64_t session = 0;  // the camera's stream session (SceneState::StreamOpened); 0 = unknown
  // False for a LiDAR foot track (a ground position with covariance, no extent): its
  // placement.size_m is a stand-in that gives a LiDAR-only object a person's size and is replaced
  // by the first measured size (a camera's box) rather than blended into it.
  bool size_measured = true;
};

struct FusedObject {
  uint64_t id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Matrix2d covariance_xy = Eigen::Matrix2d::Identity();
  Eigen::Vector3d size_m = Eigen::Vector3d::Zero();
  double heading_rad = 0;
  ObjectKind kind = ObjectKind::kUnknown;
  ObjectShape shape = ObjectShape::kBillboard;
  std::deque<Eigen::Vector3d> path;
  std::map<std::string, std::pair<uint32_t, int64_t>> cameras;  // camera -> (track id, last seen ns)
  std::string newest_camera;
  int64_t first_seen_ns = 0, last_seen_ns = 0;
  Eigen::Vector3d heading_anchor = Eigen::Vector3d::Zero();
  int kind_votes[3] = {0, 0, 0};
  bool size_measured = false;  // some observation measured size_m (else it is a LiDAR stand-in)
};

class ObjectFusion {
 public:
  explicit ObjectFusion(ObjectOptions options = {});

  // Folds one placement in; returns the id of the object it joined or started.
  uint64_t Observe(const ObjectObservation& observation);
  // Drops objects (and camera ties) unseen for forget_s before now_ns; merges objects within the gate
  // (candidate pairs by a sweep along the wider ground axis: N log N for objects spread over the
  // site, not N^2).
  void Expire(int64_t now_ns);
  // Objects seen within forget_s of now_ns.
  std::vector<const FusedObject*> Live(int64_t now_ns) const;
  size_t size() const { return objects_.size(); }
  // The object with this id, live or not yet expired; nullptr when there is none.
  const FusedObject* Find(uint64_t id) const;
  // The live object a sensor's track (of a stream session) is tied to now, 0 when none (merges
  // re-point ties, so this follows an object that was merged into another).
  uint64_t TiedObject(const std::string& camera_id, uint64_t session, uint32_t track_id) const;

 private:
  void Update(FusedObject& object, const ObjectObservation& observation);
  bool Within(const FusedObject& object, const Eigen::Vector3d& p, const Eigen::Matrix2d& cov) const;
  // Index of the ties: (camera, session, track) -> object id, kept in step with FusedObject::cameras.
  using TrackKey = std::tuple<std::string, uint64_t, uint32_t>;
  // Re-points (to != 0) or drops (to == 0) every tie of `camera` to object `from`.
  void Retie(const std::string& camera, uint64_t from, uint64_t to);
  ObjectOptions options_;
  std::map<uint64_t, FusedObject> objects_;
  std::map<TrackKey, uint64_t> ties_;
  uint64_t next_id_ = 1;
};

}  // namespace ave
