// Logging set-up shared by every tool: spdlog to stderr (stdout is reserved
// for results and --json), level from --log-level or VISTREAM_LOG_LEVEL.
#pragma once

#include <string>

namespace vistream {

// Accepts trace, debug, info, warn, error, critical, off. Throws InputError
// naming the value on anything else.
void initLogging(const std::string& level);

}  // namespace vistream
