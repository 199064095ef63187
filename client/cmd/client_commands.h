// `vistream-client`: the rendering client. main() only calls runClientTool(); tests may call it
// too.
#pragma once

namespace vistream {

// Returns 0 on success, 1 on bad input (printed to stderr), 2 on bad usage.
int runClientTool(int argc, char** argv);

}  // namespace vistream
