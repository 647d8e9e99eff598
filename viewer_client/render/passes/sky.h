#pragma once
// Internal to ave_render: the sky dome (elevation -10 to 90 degrees, inward facing) centred on the
// bottom centre of the static model's box, drawn into the G-buffer in the view's clear colour
// (sky marker colour r < 0) so projectors reach it within their far plane (DisplayOptions::sky).
#include <utility>

#include <Eigen/Core>

#include "viewer_client/render/passes/gl_util.h"
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class Sky {
 public:
  // The dome around an empty model (the origin, radius max(100 m, sky_radius_m)).
  explicit Sky(const RendererOptions& options);

  // Re-centres the dome on a new static model's box.
  void Place(const Bounds& static_bounds);
  // The dome with the bound program and state (only while `on`).
  void Draw(bool on) const;
  // Adds the dome's box to `scene` (when `on`).
  void AddTo(Bounds& scene, bool on) const;

 private:
  const double radius_option_m_;
  MeshBuffers mesh_;
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  double radius_m_ = 0;
};

}  // namespace ave::viewer::internal
