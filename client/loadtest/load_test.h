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
// end it turns round and walks back, so it never teleports. Path files are in file coordinates; the
// client converts with the Welcome's local origin.
//
// Failing honestly: a client fails if its connection, handshake or stream
// ends with an error, or if it never gets its initial load (the first time
// it stands in a cell whose CellReady it has, which says it holds that
// cell's whole face set; the cell may be its first or one it walked into). A
// run where any client failed is a failed run (LoadTestReport::failure), so
// a server that serves nothing never reports success.
//
// Bounded time: the run ends by `durationS + graceS` seconds after it
// started, whatever the server does (accepts and never answers, answers the
// Hello and then stalls, stops reading). At that deadline every socket still
// open is closed and its client counted as cut off.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

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
  double fps = 10.0;       // poses per second per client
  size_t checkEvery = 10;  // frames between visibility checks (0: never)
  int checkRaysX = 32, checkRaysY = 24;
  float radius = 0.0f;  // near-field radius asked for (0: the server's)
  uint64_t memoryBudget = 0;
  // Seconds between Stats frames asked of the server (0: its interval). A
  // walking user needs none; the load test reads the server's CPU from them.
  float statsIntervalS = 10.0f;
  bool avatars = true;  // ask for avatar updates
  // A connection lost while walking is made again (backoff 0.1 s doubling
  // to 2 s), naming the faces still held; off: the client fails.
  bool reconnect = true;
  std::string token;
  unsigned threads = 1;
  // Seconds from the start of a client's TCP connect to the server's Welcome;
  // a client without a Welcome by then fails ("handshake").
  double connectTimeoutS = 10.0;
  // Seconds after durationS before the run is cut off (see above); unset:
  // connectTimeoutS + kDefaultGraceBeyondConnectS, which a server that
  // answers within the connect timeout never reaches.
  std::optional<double> graceS;
  const Scene* scene = nullptr;  // local copy for visibility checks; null: no checks
};

// What the default grace allows beyond the connect timeout: the final Bye
// (flushed for 0.2 s) and scheduling noise.
inline constexpr double kDefaultGraceBeyondConnectS = 2.0;

struct LoadTestReport {
  nlohmann::json json;  // the keys documented in README.md ("vistream-loadtest")
  // One line saying why the run failed (how many clients failed, for which
  // reasons, the first error); empty when every client connected, got its
  // initial load and finished without an error.
  std::string failure;
};

// Runs the test; throws InputError on bad options. Connection failures,
// protocol errors, clients never loaded and clients cut off at the deadline
// are counted in the report's `errors` (one per failed client) and summed up
// in `failure`, not thrown. Returns by durationS + graceS after the clients
// start connecting (plus at most 2 s to close their sockets); resolving the
// host and building the ray query for `scene` come before that.
LoadTestReport runLoadTest(const LoadTestOptions& options);

}  // namespace vistream
