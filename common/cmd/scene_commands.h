// `vistream-scene`: generate, inspect and sample scenes. The executable's
// main() only calls runSceneTool(); tests call it too.
#pragma once

namespace vistream {

// Returns the process exit status: 0 on success, 1 on bad input (the error is
// printed to stderr), 2 on bad usage.
int runSceneTool(int argc, char** argv);

}  // namespace vistream
