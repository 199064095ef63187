// `vistream-pvs`: the PVS service's command-line tool. main() only calls
// runPvsTool(); tests call it too.
#pragma once

namespace vistream {

// Returns 0 on success, 1 on bad input (printed to stderr), 2 on bad usage.
int runPvsTool(int argc, char** argv);

}  // namespace vistream
