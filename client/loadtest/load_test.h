// The headless load tester: N simulated clients over real TCP, each walking a
// path, with no rendering. Measures what a walkthrough user would feel:
// bytes received, the delay between entering a view cell and holding its
// whole face set (CellReady), and visibility misses: every K frames a client
// casts rays through its view frustum into its local copy of the scene and
// counts the faces it sees within its near-field radius that it does not
// hold yet.
//
// Time: each client sends a Pose every 1/fps seconds of wall time; its
// position is the path's at (start offset + elapsed * speed); past the path's
// end it turns round and walks back, so it never teleports. Path files are in file coordinates; the client converts with the
// Welcome's local origin.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/generate/path.h"
#include "common/scene/scene.h"

namespace vistream {

struct LoadTestOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 7070;
  size_t clients = 10;
  std::vector<std::vector<PathSample>> paths;  // one (all clients share it) or one per client
  double speed = 1.0;
  double durationS = 10.0;
  double fps = 10.0;              // poses per second per client
  size_t checkEvery = 10;         // frames between visibility checks (0: never)
  int checkRaysX = 32, checkRaysY = 24;
  float radius = 0.0f;            // near-field radius asked for (0: the server's)
  uint64_t memoryBudget = 0;
  bool avatars = true;            // ask for avatar updates
  std::string token;
  unsigned threads = 1;
  double connectTimeoutS = 10.0;
  const Scene* scene = nullptr;   // local copy for visibility checks; null: no checks
};

struct LoadTestReport {
  nlohmann::json json;  // the keys documented in README.md ("vistream-loadtest")
};

// Runs the test; throws InputError on bad options. Connection failures and
// protocol errors are counted in the report's `errors`, not thrown.
LoadTestReport runLoadTest(const LoadTestOptions& options);

}  // namespace vistream
