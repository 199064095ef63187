// vistream-loadtest: N simulated clients walking through a scene over TCP
// (see client/loadtest/load_test.h). Exit codes: 0 when every client
// connected, got its initial load and finished cleanly; 1 for bad input or a
// failed run (the report is still printed on stdout, and one line
// "vistream-loadtest: error: ..." on stderr says why); 2 for bad usage.
#include "client/cmd/loadtest_commands.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <cstdio>
#include <fstream>
#include <iostream>

#include "client/loadtest/load_test.h"
#include "common/cmd/cli.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/world/free_space.h"
#include "common/world/static_world.h"

namespace vistream {
namespace {

void checkHostResolves(const std::string& host) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::resolver resolver(io);
  boost::system::error_code ec;
  resolver.resolve(host, "", ec);
  if (ec)
    throwInputError(InputErrorCode::Unreachable, "--host {}: cannot resolve it: {}", host,
                    ec.message());
}

}  // namespace

int runLoadTestTool(int argc, char** argv) {
  CLI::App app{
      "vistream-loadtest: simulated clients walking through a scene served by vistream-server, "
      "over real "
      "TCP, without rendering. Prints bytes per client, CellReady latency and visibility misses."};
  std::string logLevel, pathFile, pathsMode, sceneSpec, tokenFile;
  bool asJson = false;
  LoadTestOptions o;
  showDefaultsInHelp(app);
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");
  app.add_option("--host", o.host, "server address");
  app.add_option("--port", o.port, "server port")->check(tcpPort());
  app.add_option("--clients", o.clients, "simulated clients")->check(atLeast<size_t>(1));
  app.add_option("--path", pathFile,
                 "path CSV (t,x,y,z,yaw_deg,pitch_deg); clients start at different points of it");
  app.add_option("--paths", pathsMode,
                 "auto: a different generated path per client (needs --scene)");
  app.add_option("--speed", o.speed, "relative walking speed")->check(nonNegative());
  app.add_option("--duration", o.durationS, "seconds each client walks")->check(positive());
  app.add_option("--fps", o.fps, "poses per second per client")->check(positive());
  app.add_option("--scene", sceneSpec,
                 "the scene, locally: enables visibility-miss checks and --paths auto");
  SceneLimits sceneLimits;
  addSceneLimitsOption(app, sceneLimits);
  GroundChoice ground;
  addGroundOption(app, ground);
  app.add_option("--check-every", o.checkEvery, "frames between visibility checks (0: none)")
      ->check(atLeast<size_t>(0));
  app.add_option("--radius", o.radius, "near-field radius to ask for in metres (0: the server's)")
      ->check(nonNegative());
  app.add_option("--memory-budget", o.memoryBudget, "client memory budget in bytes (0: unlimited)")
      ->check(atLeast<uint64_t>(0));
  app.add_option("--stats-interval", o.statsIntervalS,
                 "seconds between the server's Stats frames to each client (0: the server's "
                 "interval; never more often than that)")
      ->check(nonNegative());
  app.add_option("--token-file", tokenFile, "auth token file (first line)");
  bool noAvatars = false;
  app.add_flag("--no-avatars", noAvatars, "do not ask for other users' avatars");
  bool noReconnect = false;
  app.add_flag("--no-reconnect", noReconnect,
               "a client whose server goes away while walking fails; without this flag it "
               "reconnects with backoff (through a proxy perhaps to another replica), naming "
               "what it holds");
  app.add_option("--threads", o.threads, "client I/O threads")->check(atLeast<unsigned>(1));
  app.add_option("--connect-timeout", o.connectTimeoutS,
                 "seconds for a client to connect and receive the Welcome")
      ->check(positive());
  double grace = -1.0;
  auto* graceOption = app.add_option("--grace", grace,
                                     "seconds after --duration at which clients still open are "
                                     "cut off and the run ends")
                          ->check(nonNegative());
  // The sentinel -1 stands for a default that follows --connect-timeout.
  graceOption->default_str(fmt::format("--connect-timeout + {:g}", kDefaultGraceBeyondConnectS));
  app.add_flag("--json", asJson, "one JSON object on stdout");
  return runToolApp("vistream-loadtest", app, argc, argv, logLevel, [&]() -> int {
    o.avatars = !noAvatars;
    o.reconnect = !noReconnect;
    if (graceOption->count() > 0) o.graceS = grace;
    if (pathFile.empty() == pathsMode.empty())
      throwInputError("give exactly one of --path P.csv and --paths auto");
    if (!pathsMode.empty() && pathsMode != "auto")
      throwInputError("--paths: expected 'auto', got '{}'", pathsMode);
    if (!tokenFile.empty()) o.token = readTokenFile(tokenFile);
    if (!pathsMode.empty() && sceneSpec.empty()) throwInputError("--paths auto needs --scene");
    // Numbers are range-checked at parse time; the host is resolved here,
    // before a scene loads.
    checkHostResolves(o.host);
    if (!pathFile.empty()) o.paths.push_back(readPath(pathFile));
    Scene scene;
    if (!sceneSpec.empty()) {
      scene = openScene(sceneSpec, sceneLimits);
      o.scene = &scene;
    }
    if (pathFile.empty()) {
      StaticWorldOptions worldOptions;
      worldOptions.ground = ground;
      const FreeSpace fs = buildStaticWorld(scene, worldOptions).freeSpace;
      PathOptions po;
      po.frames = size_t(std::max(2.0, 30.0 * (o.durationS * std::max(1.0, o.speed) + 2.0)));
      const std::vector<glm::ivec2> goals = goalColumns(fs, po);  // one for every walk
      for (size_t i = 0; i < o.clients; ++i) {
        po.seed = 1000 + i;
        o.paths.push_back(generatePath(scene, fs, goals, po));
      }
    }
    spdlog::info("{} clients walking for {:.0f} s at speed {:.2f} against {}:{}", o.clients,
                 o.durationS, o.speed, o.host, o.port);
    const LoadTestReport r = runLoadTest(o);
    const auto& j = r.json;
    if (asJson) {
      std::cout << j.dump() << "\n";
    } else {
      auto pct = [](const nlohmann::json& p) {
        return p["count"].get<size_t>() == 0
                   ? std::string("-")
                   : fmt::format("{:.1f} / {:.1f} / {:.1f}", p["p50"].get<double>(),
                                 p["p95"].get<double>(), p["p99"].get<double>());
      };
      fmt::print("{:<34} {}\n", "clients", j["clients"].get<size_t>());
      fmt::print("{:<34} {:.1f}\n", "duration (s)", j["duration_s"].get<double>());
      fmt::print("{:<34} {:.0f}\n", "bytes per client per second",
                 j["bytes_per_client_per_s"].get<double>());
      for (const auto& [type, bytes] : j["bytes_by_type"].items())
        fmt::print("{:<34} {:.0f}\n", "  bytes/client/s in " + type,
                   bytes.get<double>() / std::max(1.0, j["bytes_received"].get<double>()) *
                       j["bytes_per_client_per_s"].get<double>());
      fmt::print("{:<34} {:.1f} ({:.1f} in Geometry frames)\n", "bytes per face",
                 j["bytes_per_face"].get<double>(), j["geometry_bytes_per_face"].get<double>());
      fmt::print("{:<34} {} of {}\n", "clients loaded", j["clients_loaded"].get<size_t>(),
                 j["clients"].get<size_t>());
      fmt::print("{:<34} {}\n", "initial load ms (p50 / p95 / p99)", pct(j["initial_load_ms"]));
      fmt::print("{:<34} {}\n", "CellReady latency ms (p50/p95/p99)",
                 pct(j["cell_ready_latency_ms"]));
      fmt::print("{:<34} {} ({} found the cell ready, {} waited)\n", "cell entries",
                 j["cell_entries"].get<uint64_t>(), j["cell_entries_ready"].get<uint64_t>(),
                 j["cell_entries_waited"].get<uint64_t>());
      fmt::print("{:<34} {}\n", "CellReady wait ms (p50/p95/p99)", pct(j["cell_ready_wait_ms"]));
      fmt::print("{:<34} {} in {} checks\n", "visibility misses",
                 j["visibility_misses"].get<uint64_t>(), j["frames_checked"].get<uint64_t>());
      fmt::print("{:<34} {} other users, {} of them on another replica\n", "avatars seen",
                 j["avatars_seen"].get<uint64_t>(),
                 j["avatars_seen_other_replica"].get<uint64_t>());
      if (j["reconnects"].get<uint64_t>() > 0) {
        fmt::print("{:<34} {} ({} clients)\n", "reconnects", j["reconnects"].get<uint64_t>(),
                   j["clients_reconnected"].get<uint64_t>());
        fmt::print("{:<34} {}\n", "failover to Welcome ms (p50/p95/p99)", pct(j["failover_ms"]));
        fmt::print("{:<34} {}\n", "failover to cell ready ms", pct(j["failover_ready_ms"]));
        fmt::print("{:<34} {}\n", "misses after reconnecting",
                   j["visibility_misses_after_reconnect"].get<uint64_t>());
      }
      fmt::print("{:<34} {}{}\n", "errors", j["errors"].get<uint64_t>(),
                 j["first_error"].get<std::string>().empty()
                     ? ""
                     : " (first: " + j["first_error"].get<std::string>() + ")");
      for (const auto& [reason, n] : j["errors_by_reason"].items())
        fmt::print("{:<34} {}\n", "  " + reason, n.get<uint64_t>());
      if (!j["cut_off_clients"].empty())
        fmt::print("{:<34} {}\n", "clients cut off at the deadline", j["cut_off_clients"].dump());
      if (!j["server_cpu_ms_per_s_per_client"].is_null())
        fmt::print("{:<34} {:.2f}\n", "server CPU ms/s per client",
                   j["server_cpu_ms_per_s_per_client"].get<double>());
    }
    if (r.failure.empty()) return 0;
    std::fflush(stdout);
    std::cout.flush();
    std::fprintf(stderr, "vistream-loadtest: error: %s\n", r.failure.c_str());
    return 1;
  });
}

}  // namespace vistream
