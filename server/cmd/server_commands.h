// `vistream-server`: the streaming server. main() only calls runServerTool(); tests may call it
// too.
#pragma once

namespace vistream {

// Returns 0 on success, 1 on bad input (printed to stderr), 2 on bad usage.
int runServerTool(int argc, char** argv);

}  // namespace vistream
