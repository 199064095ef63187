// Logging set-up shared by every tool: spdlog to stderr (stdout is reserved
// for results and --json), level from --log-level or VISTREAM_LOG_LEVEL.
#pragma once

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace vistream {

// Accepts trace, debug, info, warn, error, critical, off. Throws InputError
// naming the value on anything else.
void initLogging(const std::string& level);

// A rate limit for a log line that outside parties can trigger at will (a
// refused or failed session, a failing accept): at most `burst` lines in each
// window of `interval`; further lines in the window are only counted, and
// the first line after the window (or flush()) reports how many were left
// out, so the log says what happened without growing with the attack.
// Thread-safe.
class LogLimiter {
 public:
  using Clock = std::chrono::steady_clock;
  explicit LogLimiter(std::string what, unsigned burst = 20,
                      Clock::duration interval = std::chrono::seconds(10));

  // Logs the message at `level` unless this window's burst is spent.
  template <class... Args>
  void log(spdlog::level::level_enum level, fmt::format_string<Args...> format, Args&&... args) {
    if (!spdlog::should_log(level) || !allow()) return;
    spdlog::log(level, format, std::forward<Args>(args)...);
  }
  template <class... Args>
  void warn(fmt::format_string<Args...> format, Args&&... args) {
    log(spdlog::level::warn, format, std::forward<Args>(args)...);
  }

  // True if a line may be logged now (and counts it); reports the lines
  // left out of an ended window first.
  bool allow();
  // Reports the lines left out of an ended window (call it from a timer so
  // the count appears even when the lines stop).
  void flush();
  uint64_t suppressed() const;  // in total, since construction

 private:
  void rollLocked(Clock::time_point now);

  const std::string what_;
  const unsigned burst_;
  const Clock::duration interval_;
  mutable std::mutex mutex_;  // guards every member below
  Clock::time_point windowStart_;
  unsigned inWindow_ = 0;
  uint64_t suppressedInWindow_ = 0, suppressedTotal_ = 0;
};

}  // namespace vistream
