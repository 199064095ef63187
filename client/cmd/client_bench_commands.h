// `vistream-client-bench`: the client benchmark. main() only calls runClientBenchTool(); tests may
// call it too.
#pragma once

namespace vistream {

// Returns 0 on success, 1 on bad input (printed to stderr), 2 on bad usage.
int runClientBenchTool(int argc, char** argv);

}  // namespace vistream
