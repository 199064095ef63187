#include "client/gl/gl_window.h"

#include <algorithm>
#include <cmath>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "common/core/error.h"
#include "common/core/view.h"

namespace vistream {
namespace {

constexpr float kTurnDegPerSecond = 90.0f;  // arrow keys
constexpr float kTurnDegPerPixel = 0.15f;   // mouse drag
constexpr float kRunFactor = 4.0f;          // Shift held
constexpr float kMaxPitchDeg = 85.0f;  // keeps the view away from the poles, where yaw degenerates

// Windows alive. GLFW is initialised with the first and terminated with the
// last; GLFW runs on the main thread only, so a plain counter is enough.
int glfwUsers = 0;

// The description of GLFW's last error, which it keeps until asked.
std::string lastGlfwError() {
  const char* description = nullptr;
  const int code = glfwGetError(&description);
  if (code == GLFW_NO_ERROR || description == nullptr) return "GLFW gave no reason";
  return description;
}

void releaseGlfw() {
  if (--glfwUsers == 0) glfwTerminate();
}

}  // namespace

struct GlWindow::Impl {
  GLFWwindow* window = nullptr;
  bool dragging = false;
  double lastX = 0.0, lastY = 0.0;  // cursor position at the last navigate() while dragging

  bool key(int k) const { return glfwGetKey(window, k) == GLFW_PRESS; }
};

GlWindow::GlWindow(const GlWindowOptions& options) : impl_(std::make_unique<Impl>()) {
  glfwGetError(nullptr);  // forget errors from before
  if (glfwUsers == 0 && glfwInit() != GLFW_TRUE)
    throwInputError("cannot open a window: no display (set DISPLAY or run under xvfb-run): {}",
                    lastGlfwError());
  ++glfwUsers;

  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_VISIBLE, options.visible ? GLFW_TRUE : GLFW_FALSE);
  glfwWindowHint(GLFW_SAMPLES, 0);
  glfwWindowHint(GLFW_DEPTH_BITS, 24);
  glfwWindowHint(GLFW_SRGB_CAPABLE, GLFW_FALSE);
  impl_->window =
      glfwCreateWindow(options.width, options.height, options.title.c_str(), nullptr, nullptr);
  if (impl_->window == nullptr) {
    const std::string reason = lastGlfwError();
    releaseGlfw();
    throwInputError("cannot open a {} x {} window with an OpenGL 3.3 core context: {}",
                    options.width, options.height, reason);
  }
  glfwMakeContextCurrent(impl_->window);
  glfwSwapInterval(options.vsync ? 1 : 0);
}

GlWindow::~GlWindow() {
  glfwDestroyWindow(impl_->window);
  releaseGlfw();
}

bool GlWindow::shouldClose() const {
  return glfwWindowShouldClose(impl_->window) == GLFW_TRUE;
}

bool GlWindow::navigate(Camera& camera, double dt, float speed) {
  glfwPollEvents();
  Impl& w = *impl_;
  if (w.key(GLFW_KEY_ESCAPE)) glfwSetWindowShouldClose(w.window, GLFW_TRUE);

  const Camera before = camera;
  const float seconds = float(dt);

  // Turning: arrow keys at a fixed rate, or the mouse while the left button is held.
  float yaw = 0.0f, pitch = 0.0f;
  if (w.key(GLFW_KEY_LEFT)) yaw += kTurnDegPerSecond * seconds;
  if (w.key(GLFW_KEY_RIGHT)) yaw -= kTurnDegPerSecond * seconds;
  if (w.key(GLFW_KEY_UP)) pitch += kTurnDegPerSecond * seconds;
  if (w.key(GLFW_KEY_DOWN)) pitch -= kTurnDegPerSecond * seconds;
  double x = 0.0, y = 0.0;
  glfwGetCursorPos(w.window, &x, &y);
  if (glfwGetMouseButton(w.window, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {
    if (w.dragging) {
      // Cursor y grows downwards: moving the mouse up looks up; moving it right turns right.
      yaw -= kTurnDegPerPixel * float(x - w.lastX);
      pitch -= kTurnDegPerPixel * float(y - w.lastY);
    }
    w.dragging = true;
    w.lastX = x;
    w.lastY = y;
  } else {
    w.dragging = false;
  }
  if (yaw != 0.0f) camera.yawDeg = std::remainder(camera.yawDeg + yaw, 360.0f);
  if (pitch != 0.0f)
    camera.pitchDeg = std::clamp(camera.pitchDeg + pitch, -kMaxPitchDeg, kMaxPitchDeg);

  // Moving: upright, so forward and back stay horizontal whatever the pitch.
  const glm::vec3 ahead(viewDirection(camera.yawDeg, 0.0));
  glm::vec3 move(0.0f);
  if (w.key(GLFW_KEY_W)) move += ahead;
  if (w.key(GLFW_KEY_S)) move -= ahead;
  if (w.key(GLFW_KEY_D)) move += camera.right();
  if (w.key(GLFW_KEY_A)) move -= camera.right();
  if (w.key(GLFW_KEY_E)) move.y += 1.0f;
  if (w.key(GLFW_KEY_Q)) move.y -= 1.0f;
  const bool run = w.key(GLFW_KEY_LEFT_SHIFT) || w.key(GLFW_KEY_RIGHT_SHIFT);
  camera.eye += move * (speed * (run ? kRunFactor : 1.0f) * seconds);

  return camera.eye != before.eye || camera.yawDeg != before.yawDeg ||
         camera.pitchDeg != before.pitchDeg;
}

void GlWindow::setTitle(const std::string& title) {
  glfwSetWindowTitle(impl_->window, title.c_str());
}

void GlWindow::swapBuffers() {
  glfwSwapBuffers(impl_->window);
}

int GlWindow::framebufferWidth() const {
  int width = 0, height = 0;
  glfwGetFramebufferSize(impl_->window, &width, &height);
  return width;
}

int GlWindow::framebufferHeight() const {
  int width = 0, height = 0;
  glfwGetFramebufferSize(impl_->window, &width, &height);
  return height;
}

}  // namespace vistream
