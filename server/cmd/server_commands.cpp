// vistream-server: streams a scene to many clients over TCP (see
// server/stream/stream_server.h and protocol/README.md).
#include "server/cmd/server_commands.h"

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/cmd/cli.h"
#include "common/generate/scene_spec.h"
#include "server/stream/stream_server.h"

namespace vistream {

int runServerTool(int argc, char** argv) {
  CLI::App app{
      "vistream-server: streams to each client the part of a scene it can see (a conservative PVS "
      "of its "
      "view cell), over TCP.\n" +
      sceneSpecHelp()};
  app.set_config("--config", "",
                 "read options from a TOML/INI file (keys are the long option names)");
  std::string logLevel, scene, pvsDb, tokenFile, policy = "visibility", portFile;
  StreamServerConfig cfg;
  StreamWorldOptions worldOptions;
  SceneLimits sceneLimits;
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");
  app.add_option("--scene", scene, "SCENE")->required();
  addSceneLimitsOption(app, sceneLimits);
  app.add_option("--pvs-db", pvsDb,
                 "baked PVS database (vistream-pvs bake); default: compute on demand");
  app.add_option("--cell-size", worldOptions.cellSize,
                 "view cell size in metres without a database (default 4)");
  app.add_option("--pvs-cache", worldOptions.pvsCacheCells, "cells whose PVS stays cached (LRU)");
  app.add_option("--bind", cfg.bindAddress, "address to listen on (default 127.0.0.1)");
  app.add_option("--port", cfg.port, "TCP port (default 7070; 0 picks a free one)");
  app.add_option("--port-file", portFile, "write the port listened on to this file");
  app.add_option("--threads", cfg.ioThreads, "I/O threads (default 2)");
  app.add_option("--workers", cfg.workerThreads, "visibility worker threads (default: all cores)");
  app.add_option("--max-clients", cfg.maxClients, "sessions at once (default 1000)");
  app.add_option("--token-file", tokenFile, "require the shared token in this file (first line)");
  app.add_flag("--pvs-only", cfg.pvsOnly, "answer PvsRequest with face IDs; send no geometry");
  app.add_option("--policy", policy,
                 "visibility (PVS within the radius) or radius (baseline: everything within it)");
  app.add_option("--radius", cfg.defaultRadius,
                 "near-field radius in metres when the client names none (default 200)");
  app.add_option("--max-client-kbps", cfg.maxClientKbps,
                 "per-client bandwidth limit in kbit/s (0: none)");
  app.add_option("--prefetch-s", cfg.prefetchSeconds,
                 "prefetch the cells the client reaches within this time");
  app.add_option("--avatar-hz", cfg.avatarHz, "avatar updates per second (default 2; 0: off)");
  app.add_option("--max-avatars", cfg.maxAvatars,
                 "nearest visible avatars per update (default 16)");
  app.add_option("--stats-interval", cfg.statsIntervalS, "seconds between stats lines");
  app.add_option("--max-frame-bytes", cfg.maxInboundFrameBytes, "largest inbound frame accepted");
  app.add_option("--send-queue-bytes", cfg.sendQueueLimitBytes,
                 "a client with more queued is not reading: closed");
  app.add_option("--hello-timeout", cfg.helloTimeoutS, "seconds a client has to say Hello");
  app.add_option("--idle-timeout", cfg.idleTimeoutS,
                 "seconds of silence before a client is closed");
  app.add_option("--max-frames-per-s", cfg.maxFramesPerSecond,
                 "inbound frames per second per client");
  app.add_option("--frame-timeout", cfg.frameTimeoutS,
                 "seconds a client has to finish a frame it has begun")
      ->capture_default_str();
  app.add_option("--max-clients-per-address", cfg.maxClientsPerAddress,
                 "sessions at once from one IP address (0: no limit; behind a proxy all clients "
                 "share its address)")
      ->capture_default_str();
  app.add_option("--max-speed", cfg.maxSpeedMps, "a Pose faster than this (m/s) is refused")
      ->capture_default_str();
  app.add_option("--pose-margin", cfg.poseMarginM,
                 "a Pose farther than this (m) outside the scene's bounds is refused")
      ->capture_default_str();
  app.add_option("--max-cell-requests", cfg.maxCellRequests,
                 "cell face sets a session may have outstanding on the worker pool")
      ->capture_default_str();
  app.add_option("--max-pvs-requests", cfg.maxPvsRequestsWaiting,
                 "PvsRequests a session may have waiting for replies; more get RateLimited")
      ->capture_default_str();
  return runToolApp("vistream-server", app, argc, argv, logLevel, [&]() -> int {
    cfg.policy = parseStreamPolicy(policy);
    if (!tokenFile.empty()) cfg.token = readTokenFile(tokenFile);
    if (!(cfg.defaultRadius > 0.0f)) throwInputError("--radius must be positive");
    if (cfg.maxClientKbps < 0.0) throwInputError("--max-client-kbps must be >= 0");
    if (cfg.ioThreads == 0) throwInputError("--threads must be at least 1");
    if (!(cfg.frameTimeoutS > 0.0)) throwInputError("--frame-timeout must be positive");
    if (!(cfg.maxSpeedMps > 0.0)) throwInputError("--max-speed must be positive");
    if (!(cfg.poseMarginM >= 0.0)) throwInputError("--pose-margin must be >= 0");
    if (cfg.maxCellRequests == 0) throwInputError("--max-cell-requests must be at least 1");
    if (cfg.maxPvsRequestsWaiting == 0) throwInputError("--max-pvs-requests must be at least 1");
    worldOptions.pvsDatabase = pvsDb;
    StreamWorld world(openScene(scene, sceneLimits), worldOptions);
    StreamServer server(world, cfg);
    server.start();
    if (!portFile.empty()) {
      const std::filesystem::path tmp = portFile + ".tmp";
      std::ofstream(tmp) << server.port() << "\n";
      std::filesystem::rename(tmp, portFile);
    }
    server.run(true);
    return 0;
  });
}

}  // namespace vistream
