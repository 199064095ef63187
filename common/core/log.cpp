#include "common/core/log.h"

#include <cstdlib>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

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
    throwInputError("unknown log level '{}' (expected trace, debug, info, warn, error, critical or off)",
                    chosen);
  auto logger = spdlog::stderr_color_mt("vistream");
  logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  spdlog::set_default_logger(logger);
  spdlog::set_level(parsed);
}

}  // namespace vistream
