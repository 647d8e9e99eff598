#pragma once
// Where the renderer draws: an OpenGL 3.3+ core context with its framebuffer, either headless (EGL
// surfaceless + an offscreen framebuffer; tests, snapshots, servers without X) or a GLFW window.
// GL, EGL and GLFW headers stay in gl_context.cc so callers of this header need none of them.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace ave::viewer {

class GlContext {
 public:
  virtual ~GlContext() = default;

  // Makes the context current on the calling thread and binds its framebuffer for drawing.
  virtual absl::Status MakeCurrent() = 0;
  // Binds the framebuffer the context presents / reads back (offscreen FBO or the window's).
  virtual void BindFramebuffer() = 0;
  virtual int framebuffer_width() const = 0;   // pixels
  virtual int framebuffer_height() const = 0;  // pixels
  // The framebuffer's colour as RGBA8, width * height * 4 bytes, rows top first (row 0 is the
  // top of the picture; GL itself reads bottom first). The context must be current.
  virtual absl::StatusOr<std::vector<uint8_t>> ReadPixels() = 0;

  // "<GL_RENDERER> | <GL_VERSION>" of the current context, for logs.
  std::string Description() const;
};

// EGL surfaceless context (Mesa EGL_PLATFORM_SURFACELESS_MESA, no X server needed) drawing into an
// offscreen framebuffer of colour RGBA8 + 24-bit depth. Current on the creating thread.
class HeadlessContext final : public GlContext {
 public:
  ~HeadlessContext() override;
  absl::Status MakeCurrent() override;
  void BindFramebuffer() override;
  int framebuffer_width() const override;
  int framebuffer_height() const override;
  absl::StatusOr<std::vector<uint8_t>> ReadPixels() override;
  // Reallocates the offscreen framebuffer (contents undefined afterwards).
  absl::Status Resize(int width, int height);

  struct Impl;

 private:
  friend absl::StatusOr<std::unique_ptr<HeadlessContext>> CreateHeadlessContext(int, int);
  explicit HeadlessContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// width, height: the offscreen framebuffer in pixels (1..16384).
absl::StatusOr<std::unique_ptr<HeadlessContext>> CreateHeadlessContext(int width, int height);

struct WindowOptions {
  std::string title = "AVE";
  int width = 1280;  // screen coordinates; the framebuffer may be larger on HiDPI screens
  int height = 720;
  bool visible = true;
  bool vsync = true;
};

// What the user did since the previous TakeInput(): enough for a fly / orbit camera.
struct WindowInput {
  Eigen::Vector2d left_drag_px = Eigen::Vector2d::Zero();   // cursor motion with the left button held
  Eigen::Vector2d right_drag_px = Eigen::Vector2d::Zero();  // ... with the right button held
  double scroll = 0;                                        // wheel steps, positive = away from the user
  // Keys held now: W/S forward/back, A/D left/right, E/Q up/down, Shift fast.
  bool forward = false, back = false, left = false, right = false, up = false, down = false, fast = false;
  std::string typed;             // printable ASCII typed since the last call ("1", "f", ...)
  bool escape_pressed = false;   // Escape went down since the last call
  // For the viewer's on-screen panel and picking (added by h7b): the cursor in framebuffer pixels
  // from the top-left corner ((-1, -1) when outside), buttons held now, presses since the last call.
  Eigen::Vector2d cursor_px = Eigen::Vector2d(-1, -1);
  bool left_down = false, right_down = false, middle_down = false;
  int left_presses = 0, middle_presses = 0;
};

// GLFW window with a 3.3 core context (needs DISPLAY; under Xvfb it gets llvmpipe).
class WindowContext final : public GlContext {
 public:
  ~WindowContext() override;
  absl::Status MakeCurrent() override;
  void BindFramebuffer() override;
  int framebuffer_width() const override;
  int framebuffer_height() const override;
  absl::StatusOr<std::vector<uint8_t>> ReadPixels() override;  // reads the back buffer: call before Swap

  void PollEvents();
  void SwapBuffers();
  bool ShouldClose() const;
  void RequestClose();
  WindowInput TakeInput();

  struct Impl;

 private:
  friend absl::StatusOr<std::unique_ptr<WindowContext>> CreateWindowContext(const WindowOptions&);
  explicit WindowContext(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Fails with a clear message when no display is set or GLFW cannot open a 3.3 core window.
absl::StatusOr<std::unique_ptr<WindowContext>> CreateWindowContext(const WindowOptions& options = {});

}  // namespace ave::viewer
