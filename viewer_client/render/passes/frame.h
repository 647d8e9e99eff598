#pragma once
// Internal to ave_render: what the passes of one Render call share, in small explicit structs
// (FrameContext for the whole call, ViewFrame per view) built by Renderer::Impl::Render, the
// orchestrator (renderer.cc). A pass reads them; it keeps its own GL objects and state.
#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <epoxy/gl.h>

#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer::internal {

class CameraSet;

// Seconds for snapshot ages: Renderer::SetClock's time, else a steady clock from creation.
class Clock {
 public:
  void Set(double now_s) { clock_s_ = now_s; }
  double Now() const { return clock_s_ ? *clock_s_ : SteadySeconds() - created_s_; }

 private:
  static double SteadySeconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }
  std::optional<double> clock_s_;
  double created_s_ = SteadySeconds();
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

// Shared by every pass of one Render call.
struct FrameContext {
  const RendererOptions& options;
  const Clock& clock;
  RenderStats& stats;
  const CameraSet& cameras;
  int width = 0, height = 0;        // the framebuffer (and the renderer's targets)
  uint64_t static_version = 0;      // StaticModel::version()
  Bounds scene;                     // static model, dynamic models and sky
  std::vector<ProjectorPass> passes;  // live (by layer), then retained snapshots
};

// One view of the frame (the View itself is passed beside it): the projector passes it may see
// and the framebuffer it goes to.
struct ViewFrame {
  std::vector<char> visible;  // per FrameContext::passes: its volume may show in the view
  bool any_live = false, any_retained = false;
  GLuint target = 0;  // the caller's draw framebuffer
  bool target_depth = false;  // it has a depth buffer (the models of a cached view need one)
};

}  // namespace ave::viewer::internal
