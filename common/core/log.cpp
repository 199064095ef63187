#include "common/core/log.h"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdlib>

#include "common/core/error.h"

namespace vistream {

void initLogging(const std::string& level) {
  std::string chosen = level;
  if (chosen.empty()) {
    const char* env = std::getenv("VISTREAM_LOG_LEVEL");
    chosen = env ? env : "info";
  }
  const auto parsed = spdlog::level::from_str(chosen);
  if (parsed == spdlog::level::off && chosen != "off")
    throwInputError(
        "unknown log level '{}' (expected trace, debug, info, warn, error, critical or off)",
        chosen);
  auto logger = spdlog::stderr_color_mt("vistream");
  logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  spdlog::set_default_logger(logger);
  spdlog::set_level(parsed);
}

LogLimiter::LogLimiter(std::string what, unsigned burst, Clock::duration interval)
    : what_(std::move(what)), burst_(burst), interval_(interval), windowStart_(Clock::now()) {}

void LogLimiter::rollLocked(Clock::time_point now) {
  if (now - windowStart_ < interval_) return;
  if (suppressedInWindow_ > 0)
    spdlog::warn("{} more {} lines left out in the last {:.0f} s", suppressedInWindow_, what_,
                 std::chrono::duration<double>(now - windowStart_).count());
  windowStart_ = now;
  inWindow_ = 0;
  suppressedInWindow_ = 0;
}

bool LogLimiter::allow() {
  std::lock_guard lock(mutex_);
  rollLocked(Clock::now());
  if (inWindow_ < burst_) {
    ++inWindow_;
    return true;
  }
  ++suppressedInWindow_;
  ++suppressedTotal_;
  return false;
}

void LogLimiter::flush() {
  std::lock_guard lock(mutex_);
  rollLocked(Clock::now());
}

uint64_t LogLimiter::suppressed() const {
  std::lock_guard lock(mutex_);
  return suppressedTotal_;
}

}  // namespace vistream
