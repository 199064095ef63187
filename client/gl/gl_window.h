// A GLFW window with an OpenGL 3.3 core context, and upright walkthrough
// navigation: W/S forward and back, A/D sideways, Q/E down and up, mouse
// (button held) or arrow keys turn, Shift runs, Escape closes.
//
// Not thread safe: GLFW wants the main thread.
#pragma once

#include <memory>
#include <string>

#include "client/render/camera.h"

namespace vistream {

struct GlWindowOptions {
  int width = 640, height = 480;
  std::string title = "vistream";
  bool visible = true;  // false: a hidden window, for rendering paths to files
  bool vsync = true;
};

class GlWindow {
 public:
  // Throws InputError (common/core/error.h) naming the reason when GLFW or
  // the context cannot be created (no display, no OpenGL 3.3).
  explicit GlWindow(const GlWindowOptions& options);
  ~GlWindow();
  GlWindow(const GlWindow&) = delete;
  GlWindow& operator=(const GlWindow&) = delete;

  bool shouldClose() const;
  // Polls events and moves/turns `camera` by the input since the last call;
  // dt in seconds; speed in m/s. Returns true if the camera moved or turned.
  bool navigate(Camera& camera, double dt, float speed);
  void setTitle(const std::string& title);
  void swapBuffers();
  int framebufferWidth() const;
  int framebufferHeight() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vistream
