#include "viewer_client/client/overlay.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <imgui.h>
#include <backends/imgui_impl_opengl3.h>

#include <Eigen/LU>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace ave::viewer {
namespace {

ImU32 StatusColor(CameraLiveness s) {
  switch (s) {
    case CameraLiveness::kLive: return IM_COL32(60, 220, 80, 255);
    case CameraLiveness::kStale: return IM_COL32(240, 200, 40, 255);
    case CameraLiveness::kLost: return IM_COL32(235, 60, 50, 255);
    default: return IM_COL32(150, 150, 150, 255);
  }
}

const char* StatusName(CameraLiveness s) {
  switch (s) {
    case CameraLiveness::kLive: return "live";
    case CameraLiveness::kStale: return "stale";
    case CameraLiveness::kLost: return "lost";
    default: return "-";
  }
}

// Text with a dark backdrop so it reads on video and on sky.
void Label(ImDrawList* dl, const Eigen::Vector2d& at, ImU32 color, const std::string& text) {
  const ImVec2 size = ImGui::CalcTextSize(text.c_str());
  const ImVec2 p(static_cast<float>(at.x()) + 6, static_cast<float>(at.y()) - size.y - 2);
  dl->AddRectFilled(ImVec2(p.x - 2, p.y - 1), ImVec2(p.x + size.x + 2, p.y + size.y + 1), IM_COL32(0, 0, 0, 150), 3);
  dl->AddText(p, color, text.c_str());
}

constexpr double kTimelineSpanS = 30;

}  // namespace

std::optional<Eigen::Vector2d> ProjectToScreen(const View& view, int framebuffer_height, const Eigen::Vector3d& p_local) {
  const Eigen::Vector4d clip = view.projection * view.view * p_local.homogeneous();
  if (!(clip.w() > 1e-9) || !clip.allFinite()) return std::nullopt;
  const Eigen::Vector3d ndc = clip.head<3>() / clip.w();
  if (std::abs(ndc.x()) > 1 || std::abs(ndc.y()) > 1 || std::abs(ndc.z()) > 1) return std::nullopt;
  const Viewport& vp = view.viewport;
  const double x = vp.x + (ndc.x() + 1) / 2 * vp.width;
  const double y_up = vp.y + (ndc.y() + 1) / 2 * vp.height;
  return Eigen::Vector2d(x, framebuffer_height - y_up);
}

std::string PickCamera(const View& view, int framebuffer_height, const std::vector<CameraView>& cameras,
                       const Eigen::Vector2d& cursor_px, double radius_px) {
  std::string best;
  double best_d = radius_px;
  for (const CameraView& cam : cameras) {
    const auto at = ProjectToScreen(view, framebuffer_height, cam.world_from_camera.translation);
    if (!at) continue;
    const double d = (*at - cursor_px).norm();
    if (d <= best_d) {
      best_d = d;
      best = cam.id;
    }
  }
  return best;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> PixelRayOfView(const View& view, int framebuffer_height,
                                                           const Eigen::Vector2d& cursor_px) {
  const Viewport& vp = view.viewport;
  const double ndc_x = 2 * (cursor_px.x() - vp.x) / vp.width - 1;
  const double ndc_y = 2 * ((framebuffer_height - cursor_px.y()) - vp.y) / vp.height - 1;
  const Eigen::Matrix4d local_from_clip = (view.projection * view.view).inverse();
  const Eigen::Vector4d a = local_from_clip * Eigen::Vector4d(ndc_x, ndc_y, -1, 1);
  const Eigen::Vector4d b = local_from_clip * Eigen::Vector4d(ndc_x, ndc_y, 1, 1);
  const Eigen::Vector3d origin = a.head<3>() / a.w();
  return {origin, (b.head<3>() / b.w() - origin).normalized()};
}

struct Overlay::Impl {
  ImGuiContext* context = nullptr;
  bool backend = false;
  ~Impl() {
    if (context == nullptr) return;
    ImGui::SetCurrentContext(context);
    if (backend) ImGui_ImplOpenGL3_Shutdown();
    ImGui::DestroyContext(context);
  }
};

absl::StatusOr<std::unique_ptr<Overlay>> Overlay::Create() {
  std::unique_ptr<Overlay> overlay(new Overlay());
  overlay->impl_ = std::make_unique<Impl>();
  overlay->impl_->context = ImGui::CreateContext();
  ImGui::SetCurrentContext(overlay->impl_->context);
  ImGuiIO& io = ImGui::GetIO();
  io.IniFilename = nullptr;  // no imgui.ini written into the working directory
  io.LogFilename = nullptr;
  ImGui::StyleColorsDark();
  ImGui::GetStyle().Alpha = 0.92f;
  if (!ImGui_ImplOpenGL3_Init("#version 330 core")) {
    return absl::UnavailableError("overlay: ImGui's OpenGL 3 backend could not start (libGL.so.1 loader)");
  }
  overlay->impl_->backend = true;
  return overlay;
}

Overlay::~Overlay() = default;

void Overlay::BeginFrame(int framebuffer_width, int framebuffer_height, const WindowInput* input, double dt_s) {
  ImGui::SetCurrentContext(impl_->context);
  ImGuiIO& io = ImGui::GetIO();
  io.DisplaySize = ImVec2(static_cast<float>(framebuffer_width), static_cast<float>(framebuffer_height));
  io.DeltaTime = static_cast<float>(std::clamp(dt_s, 1e-4, 1.0));
  // ImGui 1.86 reads the mouse state from io fields each frame.
  if (input != nullptr) {
    io.MousePos = ImVec2(static_cast<float>(input->cursor_px.x()), static_cast<float>(input->cursor_px.y()));
    io.MouseDown[0] = input->left_down || input->left_presses > 0;
    io.MouseDown[1] = input->right_down;
    io.MouseWheel = static_cast<float>(input->scroll);
    for (char c : input->typed) io.AddInputCharacter(static_cast<unsigned>(c));
  } else {
    io.MousePos = ImVec2(-FLT_MAX, -FLT_MAX);
    io.MouseDown[0] = io.MouseDown[1] = false;
  }
  ImGui_ImplOpenGL3_NewFrame();
  ImGui::NewFrame();
}

bool Overlay::WantsMouse() const {
  ImGui::SetCurrentContext(impl_->context);
  return ImGui::GetIO().WantCaptureMouse;
}

void Overlay::Panel(const std::vector<CameraView>& cameras, const OverlayStats& stats, int64_t now_ns,
                    OverlayState& state) {
  if (!state.panel) return;
  ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowBgAlpha(0.78f);
  ImGui::Begin("AVE", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  ImGui::PushItemWidth(150);
  const std::string rate = stats.fps > 0 ? absl::StrFormat("%.1f frames/s", stats.fps) : std::string("first frame");
  ImGui::Text("%s   %d of %zu cameras streaming   %.0f kB/s", rate.c_str(), stats.cameras_receiving, cameras.size(),
              stats.jpeg_bytes_per_s / 1e3);
  if (ImGui::CollapsingHeader("Display", ImGuiTreeNodeFlags_DefaultOpen)) {
    const char* policies[] = {"blend by view angle", "best view", "last wins"};
    int policy = static_cast<int>(state.display.overlap);
    if (ImGui::Combo("overlap", &policy, policies, IM_ARRAYSIZE(policies))) {
      state.display.overlap = static_cast<OverlapPolicy>(policy);
    }
    float half_life = static_cast<float>(state.display.retention_half_life_s);
    if (ImGui::SliderFloat("retention half-life (s)", &half_life, 0, 600, "%.0f")) {
      state.display.retention_half_life_s = half_life;
    }
    ImGui::Checkbox("age tint", &state.display.tint_by_age);
    ImGui::SameLine();
    ImGui::Checkbox("sky", &state.display.sky);
    ImGui::Checkbox("frustums", &state.frustums);
    ImGui::SameLine();
    ImGui::Checkbox("paths", &state.paths);
    ImGui::SameLine();
    ImGui::Checkbox("labels", &state.annotations);
    ImGui::Checkbox("data selection (frames in view only)", &state.select_data);
  }
  if (ImGui::CollapsingHeader("Cameras", ImGuiTreeNodeFlags_DefaultOpen)) {
    // One row per camera: status dot, name (click: select), lock buttons, and its time line (one
    // tick per frame received in the last 30 s, newest at the right).
    const float line_w = 150;
    for (size_t i = 0; i < cameras.size() && i < 64; ++i) {
      const CameraView& cam = cameras[i];
      ImGui::PushID(static_cast<int>(i));
      ImDrawList* dl = ImGui::GetWindowDrawList();
      const ImVec2 p = ImGui::GetCursorScreenPos();
      const float h = ImGui::GetTextLineHeight();
      dl->AddCircleFilled(ImVec2(p.x + h / 2, p.y + h / 2 + 1), h / 3, StatusColor(cam.status));
      ImGui::Dummy(ImVec2(h, h));
      ImGui::SameLine();
      const std::string label = absl::StrCat(cam.id, " (", StatusName(cam.status), ")");
      if (ImGui::Selectable(label.c_str(), cam.id == state.selected_camera, 0, ImVec2(170, 0))) {
        state.selected_camera = cam.id == state.selected_camera ? std::string() : cam.id;
      }
      for (int cell = 0; cell < 3; ++cell) {
        ImGui::SameLine();
        const bool on = state.locked[cell] == cam.id;
        if (on) ImGui::PushStyleColor(ImGuiCol_Button, IM_COL32(40, 120, 200, 255));
        if (ImGui::SmallButton(absl::StrCat(cell + 1).c_str())) state.locked[cell] = on ? std::string() : cam.id;
        if (on) ImGui::PopStyleColor();
      }
      ImGui::SameLine();
      const ImVec2 q = ImGui::GetCursorScreenPos();
      dl->AddRectFilled(q, ImVec2(q.x + line_w, q.y + h), IM_COL32(30, 30, 30, 200));
      for (int64_t t : cam.recent_frame_times_ns) {
        const double age_s = (now_ns - t) * 1e-9;
        if (age_s < 0 || age_s > kTimelineSpanS) continue;
        const float x = q.x + line_w * static_cast<float>(1 - age_s / kTimelineSpanS);
        dl->AddLine(ImVec2(x, q.y + 2), ImVec2(x, q.y + h - 2), StatusColor(cam.status));
      }
      ImGui::Dummy(ImVec2(line_w, h));
      ImGui::PopID();
    }
    ImGui::TextDisabled("time line: frames received, last %.0f s; 1 2 3: lock a view", kTimelineSpanS);
  }
  ImGui::Text("subscriptions: %llu  servers: %d", static_cast<unsigned long long>(stats.subscriptions), stats.servers);
  ImGui::PopItemWidth();
  ImGui::End();
}

void Overlay::Annotate(const View& view, int framebuffer_height, const std::vector<CameraView>& cameras,
                       const std::vector<ObjectView>& objects, const OverlayState& state) {
  ImDrawList* dl = ImGui::GetBackgroundDrawList();
  const Viewport& vp = view.viewport;
  const ImVec2 clip_min(static_cast<float>(vp.x), static_cast<float>(framebuffer_height - vp.y - vp.height));
  const ImVec2 clip_max(static_cast<float>(vp.x + vp.width), static_cast<float>(framebuffer_height - vp.y));
  dl->PushClipRect(clip_min, clip_max, true);
  dl->AddRect(clip_min, clip_max, IM_COL32(20, 20, 20, 255));
  auto at = [&](const Eigen::Vector3d& p) { return ProjectToScreen(view, framebuffer_height, p); };
  auto im = [](const Eigen::Vector2d& v) { return ImVec2(static_cast<float>(v.x()), static_cast<float>(v.y())); };
  if (state.paths) {
    for (const ObjectView& o : objects) {
      for (size_t k = 1; k < o.path.size(); ++k) {
        const auto a = at(o.path[k - 1] + Eigen::Vector3d(0, 0, 0.1)), b = at(o.path[k] + Eigen::Vector3d(0, 0, 0.1));
        if (a && b) dl->AddLine(im(*a), im(*b), IM_COL32(255, 120, 40, 230), 2);
      }
    }
  }
  if (state.annotations) {
    for (const ObjectView& o : objects) {
      if (const auto p = at(o.position + Eigen::Vector3d(0, 0, std::max(o.size.z(), 0.5)))) {
        Label(dl, *p, IM_COL32(255, 200, 150, 255), absl::StrCat("#", o.id));
      }
    }
    for (const CameraView& cam : cameras) {
      const auto p = at(cam.world_from_camera.translation);
      if (!p) continue;
      const bool selected = cam.id == state.selected_camera;
      dl->AddCircleFilled(im(*p), selected ? 6.0f : 4.0f, StatusColor(cam.status));
      if (selected) dl->AddCircle(im(*p), 10, IM_COL32(255, 255, 255, 255), 0, 2);
      Label(dl, *p, selected ? IM_COL32(255, 255, 255, 255) : IM_COL32(220, 230, 255, 255),
            cam.name.empty() || cam.name == cam.id ? cam.id : absl::StrCat(cam.id, " ", cam.name));
    }
  }
  dl->PopClipRect();
}

void Overlay::EndFrame() {
  ImGui::SetCurrentContext(impl_->context);
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
}

void Overlay::DiscardFrame() {
  ImGui::SetCurrentContext(impl_->context);
  ImGui::EndFrame();
}

}  // namespace ave::viewer
