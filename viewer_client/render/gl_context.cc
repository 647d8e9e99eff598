#include "viewer_client/render/gl_context.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>

#include <epoxy/egl.h>
#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "absl/status/status.h"

namespace ave::viewer {
namespace {

// Reads the bound read framebuffer's colour and flips it to rows top first.
std::vector<uint8_t> ReadRgbaTopFirst(int width, int height) {
  std::vector<uint8_t> bottom_first(static_cast<size_t>(width) * height * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, bottom_first.data());
  std::vector<uint8_t> top_first(bottom_first.size());
  const size_t row = static_cast<size_t>(width) * 4;
  for (int y = 0; y < height; ++y) {
    std::memcpy(&top_first[static_cast<size_t>(y) * row], &bottom_first[static_cast<size_t>(height - 1 - y) * row], row);
  }
  return top_first;
}

absl::Status CheckSize(int width, int height) {
  if (width <= 0 || height <= 0 || width > 16384 || height > 16384) {
    return absl::InvalidArgumentError("framebuffer size " + std::to_string(width) + "x" + std::to_string(height) +
                                      " must be in 1..16384");
  }
  return absl::OkStatus();
}

std::string EglErrorText() {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "EGL error 0x%04x", static_cast<unsigned>(eglGetError()));
  return buffer;
}

// EGL displays are per process and eglTerminate ends them for every context: count users.
std::mutex g_egl_mutex;
int g_egl_users = 0;

}  // namespace

std::string GlContext::Description() const {
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return std::string(renderer ? renderer : "?") + " | " + (version ? version : "?");
}

// ---------------------------------------------------------------------------------------------
// Headless (EGL surfaceless or EGL device + FBO)

struct HeadlessContext::Impl {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  GLuint fbo = 0, color_rb = 0, depth_rb = 0;
  int width = 0, height = 0;

  absl::Status AllocateFramebuffer(int w, int h) {
    if (fbo == 0) {
      glGenFramebuffers(1, &fbo);
      glGenRenderbuffers(1, &color_rb);
      glGenRenderbuffers(1, &depth_rb);
    }
    glBindRenderbuffer(GL_RENDERBUFFER, color_rb);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
    glBindRenderbuffer(GL_RENDERBUFFER, depth_rb);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH24_STENCIL8, w, h);  // stencil: the renderer's masks
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_STENCIL_ATTACHMENT, GL_RENDERBUFFER, depth_rb);
    const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE) {
      return absl::InternalError("headless framebuffer incomplete (status " + std::to_string(status) + ")");
    }
    width = w;
    height = h;
    return absl::OkStatus();
  }

  ~Impl() {
    if (context != EGL_NO_CONTEXT) {
      // Another context current on this thread stays current afterwards.
      const EGLContext previous = eglGetCurrentContext();
      eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context);
      if (fbo != 0) {
        glDeleteFramebuffers(1, &fbo);
        glDeleteRenderbuffers(1, &color_rb);
        glDeleteRenderbuffers(1, &depth_rb);
      }
      const bool restore = previous != EGL_NO_CONTEXT && previous != context;
      eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, restore ? previous : EGL_NO_CONTEXT);
      eglDestroyContext(display, context);
    }
    if (display != EGL_NO_DISPLAY) {
      std::lock_guard<std::mutex> lock(g_egl_mutex);
      if (--g_egl_users == 0) eglTerminate(display);
    }
  }
};

namespace {

// The headless display: Mesa's surfaceless platform (llvmpipe here, or Mesa's GPU drivers), or a
// GPU's EGL device (EGL_EXT_platform_device: NVIDIA's driver on a server without Mesa or a
// display). AVE_EGL_PLATFORM=surfaceless|device picks one; by default surfaceless where the client
// extensions offer it, else the first EGL device.
absl::StatusOr<EGLDisplay> OpenHeadlessDisplay() {
  const char* client_extensions = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  const std::string extensions = client_extensions ? client_extensions : "";
  const bool has_surfaceless = extensions.find("EGL_MESA_platform_surfaceless") != std::string::npos;
  const bool has_device = extensions.find("EGL_EXT_platform_device") != std::string::npos;
  const char* env = std::getenv("AVE_EGL_PLATFORM");
  const std::string wanted = env ? env : "";
  if (!wanted.empty() && wanted != "surfaceless" && wanted != "device") {
    return absl::InvalidArgumentError("AVE_EGL_PLATFORM='" + wanted + "': expected surfaceless or device");
  }
  const bool use_device = wanted == "device" || (wanted.empty() && !has_surfaceless && has_device);
  if (use_device ? !has_device : !has_surfaceless) {
    return absl::UnavailableError(use_device ? "EGL: no device platform (EGL_EXT_platform_device)"
                                             : "EGL: no surfaceless platform (is libegl-mesa0 installed?)");
  }
  // Through eglGetProcAddress: epoxy only dispatches EGL 1.5 entry points once a display says
  // it is 1.5, and there is no display yet. nullptr is EGL_DEFAULT_DISPLAY.
  auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (get_platform_display == nullptr) {
    return absl::UnavailableError("EGL: no eglGetPlatformDisplayEXT (is libegl-mesa0 installed?)");
  }
  EGLDisplay display = EGL_NO_DISPLAY;
  if (use_device) {
    auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    EGLDeviceEXT devices[8];
    EGLint count = 0;
    if (query_devices == nullptr || !query_devices(8, devices, &count) || count < 1) {
      return absl::UnavailableError("EGL: no EGL device (eglQueryDevicesEXT): " + EglErrorText());
    }
    display = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[0], nullptr);
  } else {
    display = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, nullptr, nullptr);
  }
  if (display == EGL_NO_DISPLAY) {
    return absl::UnavailableError(std::string("EGL: no ") + (use_device ? "device" : "surfaceless") +
                                  " display: " + EglErrorText());
  }
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) {
    return absl::UnavailableError(std::string("EGL: eglInitialize on the ") + (use_device ? "device" : "surfaceless") +
                                  " display failed: " + EglErrorText());
  }
  return display;
}

}  // namespace

absl::StatusOr<std::unique_ptr<HeadlessContext>> CreateHeadlessContext(int width, int height) {
  if (absl::Status s = CheckSize(width, height); !s.ok()) return s;
  auto impl = std::make_unique<HeadlessContext::Impl>();
  {
    std::lock_guard<std::mutex> lock(g_egl_mutex);
    absl::StatusOr<EGLDisplay> display = OpenHeadlessDisplay();
    if (!display.ok()) return display.status();
    impl->display = *display;
    ++g_egl_users;
  }
  if (!eglBindAPI(EGL_OPENGL_API)) return absl::UnavailableError("EGL: desktop OpenGL API not available: " + EglErrorText());
  // EGL_SURFACE_TYPE defaults to EGL_WINDOW_BIT, which surfaceless configs lack: ask for none.
  const EGLint config_attribs[] = {EGL_SURFACE_TYPE, 0, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint config_count = 0;
  if (!eglChooseConfig(impl->display, config_attribs, &config, 1, &config_count) || config_count < 1) {
    return absl::UnavailableError("EGL: no config with desktop OpenGL: " + EglErrorText());
  }
  // 4.3 core where the driver has it (the renderer's view cache needs it), else 3.3 core.
  for (const EGLint version : {43, 33}) {
    const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, version / 10, EGL_CONTEXT_MINOR_VERSION,
                                      version % 10, EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                      EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    impl->context = eglCreateContext(impl->display, config, EGL_NO_CONTEXT, context_attribs);
    if (impl->context != EGL_NO_CONTEXT) break;
  }
  if (impl->context == EGL_NO_CONTEXT) {
    return absl::UnavailableError("EGL: cannot create an OpenGL 3.3 core context: " + EglErrorText());
  }
  if (!eglMakeCurrent(impl->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl->context)) {
    return absl::UnavailableError("EGL: surfaceless eglMakeCurrent failed (EGL_KHR_surfaceless_context?): " +
                                  EglErrorText());
  }
  if (absl::Status s = impl->AllocateFramebuffer(width, height); !s.ok()) return s;
  glViewport(0, 0, width, height);
  return std::unique_ptr<HeadlessContext>(new HeadlessContext(std::move(impl)));
}

HeadlessContext::HeadlessContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
HeadlessContext::~HeadlessContext() = default;

absl::Status HeadlessContext::MakeCurrent() {
  eglBindAPI(EGL_OPENGL_API);  // per thread
  if (!eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl_->context)) {
    return absl::InternalError("EGL: eglMakeCurrent failed: " + EglErrorText());
  }
  BindFramebuffer();
  return absl::OkStatus();
}

void HeadlessContext::BindFramebuffer() { glBindFramebuffer(GL_FRAMEBUFFER, impl_->fbo); }
int HeadlessContext::framebuffer_width() const { return impl_->width; }
int HeadlessContext::framebuffer_height() const { return impl_->height; }

absl::StatusOr<std::vector<uint8_t>> HeadlessContext::ReadPixels() {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, impl_->fbo);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  std::vector<uint8_t> pixels = ReadRgbaTopFirst(impl_->width, impl_->height);
  if (const GLenum error = glGetError(); error != GL_NO_ERROR) {
    return absl::InternalError("glReadPixels failed with GL error " + std::to_string(error));
  }
  return pixels;
}

absl::Status HeadlessContext::Resize(int width, int height) {
  if (absl::Status s = CheckSize(width, height); !s.ok()) return s;
  return impl_->AllocateFramebuffer(width, height);
}

// ---------------------------------------------------------------------------------------------
// GLFW window

namespace {
std::mutex g_glfw_mutex;
int g_glfw_users = 0;
}  // namespace

struct WindowContext::Impl {
  GLFWwindow* window = nullptr;
  WindowInput pending;
  double last_x = 0, last_y = 0;
  bool have_cursor = false;

  ~Impl() {
    if (window != nullptr) glfwDestroyWindow(window);
    std::lock_guard<std::mutex> lock(g_glfw_mutex);
    if (--g_glfw_users == 0) glfwTerminate();
  }

  static Impl* From(GLFWwindow* w) { return static_cast<Impl*>(glfwGetWindowUserPointer(w)); }
};

absl::StatusOr<std::unique_ptr<WindowContext>> CreateWindowContext(const WindowOptions& options) {
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((display == nullptr || *display == '\0') && (wayland == nullptr || *wayland == '\0')) {
    return absl::FailedPreconditionError("GLFW: no DISPLAY set; use the headless context (or run under Xvfb)");
  }
  if (options.width <= 0 || options.height <= 0) return absl::InvalidArgumentError("window size must be positive");
  {
    std::lock_guard<std::mutex> lock(g_glfw_mutex);
    if (g_glfw_users == 0 && glfwInit() != GLFW_TRUE) {
      const char* description = nullptr;
      glfwGetError(&description);
      return absl::UnavailableError(std::string("GLFW: init failed: ") + (description ? description : "?"));
    }
    ++g_glfw_users;
  }
  auto impl = std::make_unique<WindowContext::Impl>();  // from here on its destructor releases GLFW
  // 4.3 core where the driver has it (the renderer's view cache needs it), else 3.3 core.
  for (const int version : {43, 33}) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, version / 10);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, version % 10);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_STENCIL_BITS, 8);  // the renderer's masks (it draws correctly without, slower)
    glfwWindowHint(GLFW_VISIBLE, options.visible ? GLFW_TRUE : GLFW_FALSE);
    impl->window = glfwCreateWindow(options.width, options.height, options.title.c_str(), nullptr, nullptr);
    if (impl->window != nullptr) break;
  }
  if (impl->window == nullptr) {
    const char* description = nullptr;
    glfwGetError(&description);
    return absl::UnavailableError(std::string("GLFW: cannot open a 3.3 core window: ") +
                                  (description ? description : "?"));
  }
  glfwMakeContextCurrent(impl->window);
  glfwSwapInterval(options.vsync ? 1 : 0);
  glfwSetWindowUserPointer(impl->window, impl.get());
  glfwSetCursorPosCallback(impl->window, [](GLFWwindow* w, double x, double y) {
    WindowContext::Impl* self = WindowContext::Impl::From(w);
    if (self->have_cursor) {
      const Eigen::Vector2d delta(x - self->last_x, y - self->last_y);
      if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) self->pending.left_drag_px += delta;
      if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS) self->pending.right_drag_px += delta;
    }
    self->last_x = x;
    self->last_y = y;
    self->have_cursor = true;
  });
  glfwSetScrollCallback(impl->window, [](GLFWwindow* w, double, double dy) { WindowContext::Impl::From(w)->pending.scroll += dy; });
  glfwSetCharCallback(impl->window, [](GLFWwindow* w, unsigned int codepoint) {
    if (codepoint >= 32 && codepoint < 127) WindowContext::Impl::From(w)->pending.typed.push_back(static_cast<char>(codepoint));
  });
  glfwSetMouseButtonCallback(impl->window, [](GLFWwindow* w, int button, int action, int) {
    if (action != GLFW_PRESS) return;
    WindowInput& in = WindowContext::Impl::From(w)->pending;
    if (button == GLFW_MOUSE_BUTTON_LEFT) ++in.left_presses;
    if (button == GLFW_MOUSE_BUTTON_MIDDLE) ++in.middle_presses;
  });
  glfwSetKeyCallback(impl->window, [](GLFWwindow* w, int key, int, int action, int) {
    if (key == GLFW_KEY_ESCAPE && action == GLFW_PRESS) WindowContext::Impl::From(w)->pending.escape_pressed = true;
  });
  return std::unique_ptr<WindowContext>(new WindowContext(std::move(impl)));
}

WindowContext::WindowContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
WindowContext::~WindowContext() = default;

absl::Status WindowContext::MakeCurrent() {
  glfwMakeContextCurrent(impl_->window);
  BindFramebuffer();
  return absl::OkStatus();
}

void WindowContext::BindFramebuffer() { glBindFramebuffer(GL_FRAMEBUFFER, 0); }

int WindowContext::framebuffer_width() const {
  int w = 0, h = 0;
  glfwGetFramebufferSize(impl_->window, &w, &h);
  return w;
}

int WindowContext::framebuffer_height() const {
  int w = 0, h = 0;
  glfwGetFramebufferSize(impl_->window, &w, &h);
  return h;
}

absl::StatusOr<std::vector<uint8_t>> WindowContext::ReadPixels() {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glReadBuffer(GL_BACK);
  std::vector<uint8_t> pixels = ReadRgbaTopFirst(framebuffer_width(), framebuffer_height());
  if (const GLenum error = glGetError(); error != GL_NO_ERROR) {
    return absl::InternalError("glReadPixels failed with GL error " + std::to_string(error));
  }
  return pixels;
}

void WindowContext::PollEvents() { glfwPollEvents(); }
void WindowContext::SwapBuffers() { glfwSwapBuffers(impl_->window); }
bool WindowContext::ShouldClose() const { return glfwWindowShouldClose(impl_->window) == GLFW_TRUE; }
void WindowContext::RequestClose() { glfwSetWindowShouldClose(impl_->window, GLFW_TRUE); }

WindowInput WindowContext::TakeInput() {
  WindowInput input = std::move(impl_->pending);
  impl_->pending = WindowInput();
  auto held = [&](int key) { return glfwGetKey(impl_->window, key) == GLFW_PRESS; };
  input.forward = held(GLFW_KEY_W);
  input.back = held(GLFW_KEY_S);
  input.left = held(GLFW_KEY_A);
  input.right = held(GLFW_KEY_D);
  input.up = held(GLFW_KEY_E);
  input.down = held(GLFW_KEY_Q);
  input.fast = held(GLFW_KEY_LEFT_SHIFT) || held(GLFW_KEY_RIGHT_SHIFT);
  auto button = [&](int b) { return glfwGetMouseButton(impl_->window, b) == GLFW_PRESS; };
  input.left_down = button(GLFW_MOUSE_BUTTON_LEFT);
  input.right_down = button(GLFW_MOUSE_BUTTON_RIGHT);
  input.middle_down = button(GLFW_MOUSE_BUTTON_MIDDLE);
  double x = 0, y = 0;
  int window_w = 0, window_h = 0;
  glfwGetCursorPos(impl_->window, &x, &y);
  glfwGetWindowSize(impl_->window, &window_w, &window_h);
  if (window_w > 0 && window_h > 0 && x >= 0 && y >= 0 && x < window_w && y < window_h) {
    input.cursor_px = {x * framebuffer_width() / window_w, y * framebuffer_height() / window_h};
  }
  return input;
}

}  // namespace ave::viewer
