// A terminal progress bar for long work (bakes, generation, ground truth).
//
// Draws on stderr only when stderr is a terminal, so logs and --json output
// stay clean; always safe to call from one thread at a time. Thread safety:
// advance() may be called concurrently (atomic counter); drawing is throttled
// to about 10 Hz.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace vistream {

class ProgressBar {
 public:
  ProgressBar(std::string label, uint64_t total);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void advance(uint64_t n = 1);
  void finish();

 private:
  void draw(bool final);

  std::string label_;
  uint64_t total_;
  std::atomic<uint64_t> done_{0};
  bool enabled_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::mutex drawMutex_;  // guards lastDraw_ and the terminal line
  std::chrono::steady_clock::time_point lastDraw_;
};

}  // namespace vistream
