// `vistream-loadtest`: the headless load tester. main() only calls runLoadTestTool(); tests may
// call it too.
#pragma once

namespace vistream {

// Returns 0 on success, 1 on bad input (printed to stderr), 2 on bad usage.
int runLoadTestTool(int argc, char** argv);

}  // namespace vistream
