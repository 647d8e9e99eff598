#include "viewer_client/client/overlay.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <epoxy/gl.h>

#include <imgui.h>
#include <backends/imgui_impl_opengl3.h>

#include <Eigen/LU>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "viewer_client/render/shader_program.h"

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

// Composites the cached overlay texture (colours premultiplied by coverage, as ImGui's blending
// leaves them over a transparent target) over the tiles it covers. Tile corners are in pixels from
// the top-left; the texture has the framebuffer's size and orientation.
constexpr char kCompositeVert[] = R"glsl(#version 330 core
layout(location = 0) in vec2 corner_px;
uniform vec2 size_px;
void main() { gl_Position = vec4(corner_px.x / size_px.x * 2.0 - 1.0, 1.0 - corner_px.y / size_px.y * 2.0, 0.0, 1.0); }
)glsl";
constexpr char kCompositeFrag[] = R"glsl(#version 330 core
uniform sampler2D overlay;
out vec4 color;
void main() { color = texelFetch(overlay, ivec2(gl_FragCoord.xy), 0); }
)glsl";

constexpr int kTilePx = 32;

// FNV-1a over ImGui's draw data: equal when the overlay would draw the same pixels.
uint64_t DrawDataSignature(const ImDrawData& data) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const void* bytes, size_t n) {
    const auto* b = static_cast<const unsigned char*>(bytes);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  mix(&data.DisplaySize, sizeof data.DisplaySize);
  for (int l = 0; l < data.CmdListsCount; ++l) {
    const ImDrawList& list = *data.CmdLists[l];
    mix(list.VtxBuffer.Data, size_t(list.VtxBuffer.Size) * sizeof(ImDrawVert));
    mix(list.IdxBuffer.Data, size_t(list.IdxBuffer.Size) * sizeof(ImDrawIdx));
    for (const ImDrawCmd& cmd : list.CmdBuffer) {
      mix(&cmd.ClipRect, sizeof cmd.ClipRect);
      mix(&cmd.TextureId, sizeof cmd.TextureId);
      mix(&cmd.ElemCount, sizeof cmd.ElemCount);
      mix(&cmd.IdxOffset, sizeof cmd.IdxOffset);
      mix(&cmd.VtxOffset, sizeof cmd.VtxOffset);
    }
  }
  return h;
}

// The 32-pixel tiles any of ImGui's triangles (within its clip rectangle) touches, as quads
// (two triangles, pixel corners from the top-left), one per horizontal run of covered tiles.
std::vector<float> CoveredTiles(const ImDrawData& data, int width, int height) {
  const int tiles_x = (width + kTilePx - 1) / kTilePx, tiles_y = (height + kTilePx - 1) / kTilePx;
  std::vector<uint8_t> covered(size_t(tiles_x) * tiles_y, 0);
  for (int l = 0; l < data.CmdListsCount; ++l) {
    const ImDrawList& list = *data.CmdLists[l];
    for (const ImDrawCmd& cmd : list.CmdBuffer) {
      if (cmd.UserCallback != nullptr) continue;
      for (unsigned i = 0; i + 2 < cmd.ElemCount; i += 3) {
        float x0 = cmd.ClipRect.z, y0 = cmd.ClipRect.w, x1 = cmd.ClipRect.x, y1 = cmd.ClipRect.y;
        for (unsigned k = 0; k < 3; ++k) {
          const ImVec2 p = list.VtxBuffer[cmd.VtxOffset + list.IdxBuffer[cmd.IdxOffset + i + k]].pos;
          x0 = std::min(x0, p.x), y0 = std::min(y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
        }
        x0 = std::max(x0, cmd.ClipRect.x), y0 = std::max(y0, cmd.ClipRect.y);
        x1 = std::min(x1, cmd.ClipRect.z), y1 = std::min(y1, cmd.ClipRect.w);
        if (!(x1 >= x0 && y1 >= y0)) continue;
        const int tx0 = std::clamp(int(x0) / kTilePx, 0, tiles_x - 1), tx1 = std::clamp(int(x1) / kTilePx, 0, tiles_x - 1);
        const int ty0 = std::clamp(int(y0) / kTilePx, 0, tiles_y - 1), ty1 = std::clamp(int(y1) / kTilePx, 0, tiles_y - 1);
        for (int ty = ty0; ty <= ty1; ++ty)
          for (int tx = tx0; tx <= tx1; ++tx) covered[size_t(ty) * tiles_x + tx] = 1;
      }
    }
  }
  std::vector<float> quads;
  for (int ty = 0; ty < tiles_y; ++ty) {
    for (int tx = 0; tx < tiles_x;) {
      if (!covered[size_t(ty) * tiles_x + tx]) {
        ++tx;
        continue;
      }
      int end = tx;
      while (end < tiles_x && covered[size_t(ty) * tiles_x + end]) ++end;
      const float x0 = float(tx * kTilePx), x1 = float(std::min(end * kTilePx, width));
      const float y0 = float(ty * kTilePx), y1 = float(std::min((ty + 1) * kTilePx, height));
      quads.insert(quads.end(), {x0, y0, x1, y0, x1, y1, x0, y0, x1, y1, x0, y1});
      tx = end;
    }
  }
  return quads;
}

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
  OverlayOptions options;
  // The cache: ImGui's pixels over a transparent target, and the tiles they cover.
  GLuint framebuffer = 0, texture = 0, program = 0, vertex_array = 0, vertex_buffer = 0;
  GLint size_uniform = -1;
  int width = 0, height = 0;
  bool valid = false;
  uint64_t signature = 0, redraws = 0;
  std::chrono::steady_clock::time_point drawn_at;
  bool input = false;  // window input this frame (mouse moved, a button, wheel or typing)
  Eigen::Vector2d last_cursor_px = Eigen::Vector2d(-1, -1);
  GLsizei tile_vertices = 0;

  ~Impl() {
    if (framebuffer != 0) glDeleteFramebuffers(1, &framebuffer);
    if (texture != 0) glDeleteTextures(1, &texture);
    if (vertex_buffer != 0) glDeleteBuffers(1, &vertex_buffer);
    if (vertex_array != 0) glDeleteVertexArrays(1, &vertex_array);
    if (program != 0) glDeleteProgram(program);
    if (context == nullptr) return;
    ImGui::SetCurrentContext(context);
    if (backend) ImGui_ImplOpenGL3_Shutdown();
    ImGui::DestroyContext(context);
  }

  // Rasterises `data` into the cache texture (resized to width x height) and records its tiles.
  void Redraw(ImDrawData* data, int w, int h) {
    if (w != width || h != height) {
      glBindTexture(GL_TEXTURE_2D, texture);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, w, h, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glBindFramebuffer(GL_FRAMEBUFFER, framebuffer);
      glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, texture, 0);
      width = w;
      height = h;
    }
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer);
    glDisable(GL_SCISSOR_TEST);
    GLfloat clear[4];
    glGetFloatv(GL_COLOR_CLEAR_VALUE, clear);
    glClearColor(0, 0, 0, 0);
    glClear(GL_COLOR_BUFFER_BIT);
    glClearColor(clear[0], clear[1], clear[2], clear[3]);
    ImGui_ImplOpenGL3_RenderDrawData(data);
    const std::vector<float> tiles = CoveredTiles(*data, w, h);
    glBindBuffer(GL_ARRAY_BUFFER, vertex_buffer);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(tiles.size() * sizeof(float)), tiles.data(), GL_STATIC_DRAW);
    tile_vertices = GLsizei(tiles.size() / 2);
    ++redraws;
  }

  // Blends the cache texture over the covered tiles of the bound framebuffer.
  void Composite() {
    if (tile_vertices == 0) return;
    glViewport(0, 0, width, height);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_CULL_FACE);
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glUseProgram(program);
    glUniform2f(size_uniform, float(width), float(height));
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, texture);
    glBindVertexArray(vertex_array);
    glDrawArrays(GL_TRIANGLES, 0, tile_vertices);
    glBindVertexArray(0);
    glUseProgram(0);
    glDisable(GL_BLEND);
  }
};

absl::StatusOr<std::unique_ptr<Overlay>> Overlay::Create(const OverlayOptions& options) {
  if (!(options.content_refresh_hz >= 0)) return absl::InvalidArgumentError("overlay: content_refresh_hz must be >= 0");
  std::unique_ptr<Overlay> overlay(new Overlay());
  overlay->impl_ = std::make_unique<Impl>();
  Impl& impl = *overlay->impl_;
  impl.options = options;
  absl::StatusOr<unsigned int> program =
      internal::BuildProgram("overlay composite (vertex)", kCompositeVert, "overlay composite (fragment)", kCompositeFrag);
  if (!program.ok()) return program.status();
  impl.program = *program;
  impl.size_uniform = glGetUniformLocation(impl.program, "size_px");
  glUseProgram(impl.program);
  glUniform1i(glGetUniformLocation(impl.program, "overlay"), 0);
  glUseProgram(0);
  glGenFramebuffers(1, &impl.framebuffer);
  glGenTextures(1, &impl.texture);
  glGenBuffers(1, &impl.vertex_buffer);
  glGenVertexArrays(1, &impl.vertex_array);
  glBindVertexArray(impl.vertex_array);
  glBindBuffer(GL_ARRAY_BUFFER, impl.vertex_buffer);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, 2 * sizeof(float), nullptr);
  glBindVertexArray(0);
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
    impl_->input = input->cursor_px != impl_->last_cursor_px || input->left_down || input->right_down ||
                   input->middle_down || input->left_presses > 0 || input->middle_presses > 0 ||
                   input->scroll != 0 || !input->typed.empty();
    impl_->last_cursor_px = input->cursor_px;
  } else {
    impl_->input = false;
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

namespace {

// The panel's Replay section (issue 18): zoom, the time line (a row per recorded camera, drag to
// seek), play / pause / live and the rate presets.
void ReplaySection(OverlayState& state) {
  using Command = OverlayState::ReplayCommand;
  static constexpr const char* kZoomNames[] = {"1 min", "10 min", "1 h", "all"};
  static constexpr double kZoomS[] = {60, 600, 3600, 0};
  for (int i = 0; i < 4; ++i) {
    if (i > 0) ImGui::SameLine();
    ImGui::RadioButton(kZoomNames[i], &state.timeline_zoom, i);
  }
  const int64_t right_ns = state.timeline_now_ns;
  int64_t left_ns = right_ns - 60'000'000'000;
  if (const double span_s = kZoomS[std::clamp(state.timeline_zoom, 0, 3)]; span_s > 0) {
    left_ns = right_ns - static_cast<int64_t>(span_s * 1e9);
  } else {
    for (const RecordedCameraSpans& camera : state.recorded.cameras) {
      if (!camera.intervals_ns.empty()) left_ns = std::min(left_ns, camera.intervals_ns.front().first);
    }
  }
  const double span_ns = std::max<double>(1, static_cast<double>(right_ns - left_ns));
  const size_t rows = std::max<size_t>(1, state.recorded.cameras.size());
  const float row_h = std::clamp(72.f / static_cast<float>(rows), 2.f, 8.f);
  const float width = std::max(200.f, ImGui::GetContentRegionAvail().x);
  const ImVec2 p0 = ImGui::GetCursorScreenPos();
  const ImVec2 size(width, row_h * static_cast<float>(rows) + 4);
  ImDrawList* dl = ImGui::GetWindowDrawList();
  auto x_of = [&](int64_t t_ns) {
    return p0.x + static_cast<float>(std::clamp((t_ns - left_ns) / span_ns, 0.0, 1.0)) * size.x;
  };
  dl->AddRectFilled(p0, ImVec2(p0.x + size.x, p0.y + size.y), IM_COL32(40, 40, 46, 255));
  for (size_t r = 0; r < state.recorded.cameras.size(); ++r) {
    const float y = p0.y + 2 + row_h * static_cast<float>(r);
    for (const auto& [from_ns, to_ns] : state.recorded.cameras[r].intervals_ns) {
      if (to_ns < left_ns) continue;
      dl->AddRectFilled(ImVec2(x_of(from_ns), y), ImVec2(std::max(x_of(to_ns), x_of(from_ns) + 1), y + row_h - 1),
                        IM_COL32(70, 170, 230, 255));
    }
  }
  const int64_t shown_ns = state.replay_time_ns > 0 ? state.replay_time_ns : right_ns;
  dl->AddLine(ImVec2(x_of(shown_ns), p0.y), ImVec2(x_of(shown_ns), p0.y + size.y),
              state.replay_time_ns > 0 ? IM_COL32(250, 210, 40, 255) : IM_COL32(235, 60, 50, 255), 2);
  state.timeline_rect_px = {p0.x, p0.y, size.x, size.y};
  ImGui::InvisibleButton("timeline", size);
  auto time_at = [&](float x) {
    return left_ns + static_cast<int64_t>(std::clamp((x - p0.x) / size.x, 0.f, 1.f) * span_ns);
  };
  if (ImGui::IsItemActive()) {
    const float x = std::clamp(ImGui::GetIO().MousePos.x, p0.x, p0.x + size.x);
    dl->AddLine(ImVec2(x, p0.y), ImVec2(x, p0.y + size.y), IM_COL32(255, 255, 255, 255), 1);
    ImGui::SetTooltip("%.1f s before now", (right_ns - time_at(x)) * 1e-9);
  }
  if (ImGui::IsItemDeactivated()) {
    state.replay_seek_ns = time_at(ImGui::GetIO().MousePos.x);
    state.replay_command = Command::kSeek;
  }
  ImGui::TextDisabled("%.0f s ago ... now; %zu cameras recorded; drag to seek", (right_ns - left_ns) * 1e-9,
                      state.recorded.cameras.size());
  if (ImGui::Button("play")) state.replay_command = Command::kPlay;
  ImGui::SameLine();
  if (ImGui::Button("pause")) state.replay_command = Command::kPause;
  const ImVec2 pause_min = ImGui::GetItemRectMin(), pause_size = ImGui::GetItemRectSize();
  state.pause_button_rect_px = {pause_min.x, pause_min.y, pause_size.x, pause_size.y};
  ImGui::SameLine();
  if (ImGui::Button("live")) state.replay_command = Command::kLive;
  const ImVec2 live_min = ImGui::GetItemRectMin(), live_size = ImGui::GetItemRectSize();
  state.live_button_rect_px = {live_min.x, live_min.y, live_size.x, live_size.y};
  ImGui::SameLine();
  ImGui::TextUnformatted(state.replay_status.c_str());
  // Rate presets: a button sets the rate exactly (a typed value never has to be parsed).
  static constexpr float kRates[] = {0.25f, 0.5f, 1, 2, 4, 8, 16};
  for (size_t i = 0; i < std::size(kRates); ++i) {
    if (i > 0) ImGui::SameLine();
    const bool active = state.replay_rate == kRates[i];
    if (active) ImGui::PushStyleColor(ImGuiCol_Button, IM_COL32(200, 150, 30, 255));
    if (ImGui::Button(absl::StrFormat("%gx", kRates[i]).c_str()) && !active) {
      state.replay_rate = kRates[i];
      state.replay_command = Command::kRate;
    }
    if (active) ImGui::PopStyleColor();
  }
}

}  // namespace

void Overlay::Panel(const std::vector<CameraView>& cameras, const OverlayStats& stats, int64_t now_ns,
                    OverlayState& state, const std::vector<LidarView>& lidars) {
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
    if (!lidars.empty()) ImGui::Checkbox("LiDAR points (by track)", &state.lidar_points);
    if (!state.avatars_locked) ImGui::Checkbox("people as avatars (v)", &state.avatars);
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
    // Rotating LiDARs (issue 16): no image to lock a view to; their status line counts the people
    // they track and the points of their newest sweep.
    for (size_t i = 0; i < lidars.size() && i < 64; ++i) {
      const LidarView& lidar = lidars[i];
      const float h = ImGui::GetTextLineHeight();
      const ImVec2 p = ImGui::GetCursorScreenPos();
      ImGui::GetWindowDrawList()->AddRectFilled(ImVec2(p.x + h / 4, p.y + h / 4 + 1), ImVec2(p.x + 3 * h / 4, p.y + 3 * h / 4 + 1),
                                                StatusColor(lidar.status));
      ImGui::Dummy(ImVec2(h, h));
      ImGui::SameLine();
      ImGui::Text("%s (LiDAR, %s): %zu people, %zu points", lidar.id.c_str(), StatusName(lidar.status),
                  lidar.tracks.size(), lidar.points ? lidar.points->p_local.size() : size_t{0});
    }
  }
  if (state.open_replay) {
    ImGui::SetNextItemOpen(true);
    state.open_replay = false;
  }
  if (ImGui::CollapsingHeader("Replay")) ReplaySection(state);
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

void Overlay::EndFrame(bool views_moved) {
  ImGui::SetCurrentContext(impl_->context);
  ImGui::Render();
  ImDrawData* data = ImGui::GetDrawData();
  Impl& impl = *impl_;
  const int w = static_cast<int>(data->DisplaySize.x), h = static_cast<int>(data->DisplaySize.y);
  if (w <= 0 || h <= 0) return;
  const uint64_t signature = DrawDataSignature(*data);
  const auto now = std::chrono::steady_clock::now();
  const bool due = impl.options.content_refresh_hz <= 0 ||
                   now - impl.drawn_at >= std::chrono::duration<double>(1 / impl.options.content_refresh_hz);
  const bool redraw = !impl.valid || w != impl.width || h != impl.height ||
                      (signature != impl.signature && (views_moved || impl.input || due));
  GLint framebuffer = 0, viewport[4];
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &framebuffer);
  glGetIntegerv(GL_VIEWPORT, viewport);
  const GLenum kept[] = {GL_BLEND, GL_SCISSOR_TEST, GL_DEPTH_TEST, GL_CULL_FACE};
  GLboolean enabled[std::size(kept)];
  for (size_t i = 0; i < std::size(kept); ++i) enabled[i] = glIsEnabled(kept[i]);
  if (redraw) {
    impl.Redraw(data, w, h);
    impl.valid = true;
    impl.signature = signature;
    impl.drawn_at = now;
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer);
  }
  impl.Composite();
  glViewport(viewport[0], viewport[1], viewport[2], viewport[3]);
  for (size_t i = 0; i < std::size(kept); ++i) (enabled[i] ? glEnable : glDisable)(kept[i]);
}

uint64_t Overlay::redraws() const { return impl_->redraws; }

void Overlay::DiscardFrame() {
  ImGui::SetCurrentContext(impl_->context);
  ImGui::EndFrame();
}

}  // namespace ave::viewer
