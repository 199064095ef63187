// vistream-server: streams a scene to many clients over TCP (see
// server/stream/stream_server.h and protocol/README.md).
#include "server/cmd/server_commands.h"

#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/cmd/cli.h"
#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "common/generate/scene_spec.h"
#include "server/stream/avatar_catalogue.h"
#include "server/stream/stream_server.h"

namespace vistream {
namespace {

// Resolves `address` and binds a socket to it (and to `port`, unless 0), so a
// wrong --bind or a port in use is reported before the scene loads. The
// socket closes again at once; the server binds for real once it is ready.
void checkListenAddress(const std::string& address, uint16_t port) {
  namespace asio = boost::asio;
  boost::system::error_code ec;
  const asio::ip::address ip = asio::ip::make_address(address, ec);
  if (ec)
    throwInputError(InputErrorCode::BadArgument,
                    "--bind {}: not an IP address ({}); give one such as 127.0.0.1 or 0.0.0.0",
                    address, ec.message());
  asio::io_context io;
  asio::ip::tcp::acceptor acceptor(io);
  const asio::ip::tcp::endpoint endpoint(ip, port);
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(asio::ip::tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (ec)
    throwInputError(InputErrorCode::BadArgument, "--bind {} --port {}: cannot listen there: {}",
                    address, port, ec.message());
}

}  // namespace

int runServerTool(int argc, char** argv) {
  CLI::App app{
      "vistream-server: streams to each client the part of a scene it can see (a conservative PVS "
      "of its "
      "view cell), over TCP.\n" +
      sceneSpecHelp()};
  showDefaultsInHelp(app);
  app.set_config("--config", "",
                 "read options from a TOML/INI file (keys are the long option names)");
  std::string logLevel, scene, pvsDb, tokenFile, policy = "visibility", portFile;
  StreamServerConfig cfg;
  StreamWorldOptions worldOptions;
  SceneLimits sceneLimits;
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");
  app.add_option("--scene", scene, "SCENE")->required();
  addSceneLimitsOption(app, sceneLimits);
  addGroundOption(app, worldOptions.ground);
  app.add_option("--pvs-db", pvsDb,
                 "baked PVS database (vistream-pvs bake); without one, PVSs are computed on "
                 "demand and the first clients in a cell wait for them");
  app.add_option("--impostor-db", worldOptions.impostorDatabase,
                 "impostor database (vistream-pvs impostors --db PVS.db --out IMP.db), baked from "
                 "--pvs-db: clients that ask for impostors get those of their cells and not the "
                 "far faces they replace");
  app.add_option("--cell-size", worldOptions.cellSize,
                 "view cell size in metres without a database")
      ->check(positive());
  std::string fusion = "auto";
  app.add_option("--fusion", fusion,
                 "without a database: occlusion horizons after the single occluders, for view "
                 "cells: auto (where the scene has solid columns), horizons or none")
      ->check(CLI::IsMember({"auto", "horizons", "none"}));
  addLightingCacheOption(app, worldOptions.lightingCache);
  bool noLighting = false;
  app.add_flag("--no-lighting", noLighting,
               "send faces without their baked colours (clients draw them flat)");
  app.add_option("--pvs-cache", worldOptions.pvsCacheCells, "cells whose PVS stays cached (LRU)")
      ->check(atLeast<size_t>(1));
  app.add_option("--bind", cfg.bindAddress, "address to listen on");
  app.add_option("--port", cfg.port, "TCP port (0 picks a free one)")->check(tcpPort(true));
  app.add_option("--port-file", portFile, "write the port listened on to this file");
  int httpPort = -1;
  std::string httpPortFile;
  app.add_option("--http-port", httpPort,
                 "serve /healthz, /metrics (Prometheus) and /pvs?point=x,y,z|cell=i,j,k (JSON) "
                 "on this TCP port (0 picks a free one; -1: no HTTP)")
      ->check(inRange<int>(-1, 65535));
  app.add_option("--http-port-file", httpPortFile, "write the HTTP port listened on to this file");
  std::string presence;
  app.add_option("--presence", presence,
                 "share users with the other replicas through Redis pub/sub "
                 "(redis://host[:port]): avatars of users on any replica appear on every one");
  app.add_option("--presence-stale", cfg.presenceStaleS,
                 "seconds of silence after which another replica's users depart")
      ->check(positive());
  app.add_option("--threads", cfg.ioThreads, "I/O threads")->check(atLeast<unsigned>(1));
  app.add_option("--workers", cfg.workerThreads, "visibility worker threads (0: all cores)")
      ->check(atLeast<unsigned>(0));
  app.add_option("--max-clients", cfg.maxClients, "sessions at once")->check(atLeast<size_t>(1));
  app.add_option("--token-file", tokenFile, "require the shared token in this file (first line)");
  app.add_flag("--pvs-only", cfg.pvsOnly, "answer PvsRequest with face IDs; send no geometry");
  app.add_option("--policy", policy,
                 "visibility (PVS within the radius) or radius (baseline: everything within it)");
  app.add_option("--radius", cfg.defaultRadius,
                 "near-field radius in metres when the client names none")
      ->check(positive());
  app.add_option("--max-client-kbps", cfg.maxClientKbps,
                 "per-client bandwidth limit in kbit/s (0: none)")
      ->check(nonNegative());
  app.add_option("--prefetch-s", cfg.prefetchSeconds,
                 "prefetch the cells the client reaches within this time")
      ->check(nonNegative());
  app.add_option("--avatar-hz", cfg.avatarHz, "avatar updates per second (0: off)")
      ->check(nonNegative());
  app.add_option("--max-avatars", cfg.maxAvatars, "nearest visible avatars per update")
      ->check(atLeast<size_t>(0));
  std::vector<std::string> avatarModels;
  float avatarHeight = 1.2f;
  app.add_option("--avatar-model", avatarModels,
                 "skinned glTF binaries (.glb) users are drawn as, taken in turn by session; "
                 "'none' offers none")
      ->default_str(std::filesystem::path(VISTREAM_DEFAULT_AVATAR).filename().string() +
                    " beside the clone (../shared/data), if it is there");
  app.add_option("--avatar-height", avatarHeight, "avatars are drawn this tall, metres")
      ->check(between(0.1, 10.0));
  app.add_option("--stats-interval", cfg.statsIntervalS, "seconds between stats lines")
      ->check(positive());
  app.add_option("--max-frame-bytes", cfg.maxInboundFrameBytes, "largest inbound frame accepted")
      ->check(atLeast<uint32_t>(1));
  app.add_option("--send-queue-bytes", cfg.sendQueueLimitBytes,
                 "a client with more queued is not reading: closed")
      ->check(atLeast<size_t>(1));
  app.add_option("--hello-timeout", cfg.helloTimeoutS, "seconds a client has to say Hello")
      ->check(positive());
  app.add_option("--idle-timeout", cfg.idleTimeoutS, "seconds of silence before a client is closed")
      ->check(positive());
  app.add_option("--max-frames-per-s", cfg.maxFramesPerSecond,
                 "inbound frames per second per client")
      ->check(atLeast<unsigned>(1));
  app.add_option("--frame-timeout", cfg.frameTimeoutS,
                 "seconds a client has to finish a frame it has begun")
      ->check(positive());
  app.add_option("--max-clients-per-address", cfg.maxClientsPerAddress,
                 "sessions at once from one IP address (0: no limit; behind a proxy all clients "
                 "share its address)")
      ->check(atLeast<size_t>(0));
  app.add_option("--max-speed", cfg.maxSpeedMps, "a Pose faster than this (m/s) is refused")
      ->check(positive());
  app.add_option("--pose-margin", cfg.poseMarginM,
                 "a Pose farther than this (m) outside the scene's bounds is refused")
      ->check(nonNegative());
  app.add_option("--max-cell-requests", cfg.maxCellRequests,
                 "cell face sets a session may have outstanding on the worker pool")
      ->check(atLeast<unsigned>(1));
  app.add_option("--unculled-after", cfg.unculledAfterS,
                 "without a database: seconds a client waits for its current cell's PVS before "
                 "it gets every face within the radius (at once while the workers are behind)")
      ->check(nonNegative());
  app.add_option("--max-pvs-requests", cfg.maxPvsRequestsWaiting,
                 "PvsRequests a session may have waiting for replies; more get RateLimited")
      ->check(atLeast<size_t>(1));
  return runToolApp("vistream-server", app, argc, argv, logLevel, [&]() -> int {
    // Numbers are range-checked at parse time; everything else that does not
    // need the scene is checked here, before seconds of loading or generating.
    cfg.policy = parseStreamPolicy(policy);
    if (!tokenFile.empty()) cfg.token = readTokenFile(tokenFile);
    checkListenAddress(cfg.bindAddress, cfg.port);
    if (pvsDb.empty())
      spdlog::info(
          "no --pvs-db: PVSs are computed on demand as clients enter cells (first the coarse "
          "cell's around them, shared, then their own), so the first clients in a cell wait for "
          "them; bake a database once with "
          "`vistream-pvs bake --scene {} --cell-size {:g} --out scene.db` and serve it with "
          "--pvs-db scene.db",
          scene, worldOptions.cellSize);
    std::vector<std::filesystem::path> avatarFiles;
    if (avatarModels.empty()) {
      if (std::filesystem::exists(VISTREAM_DEFAULT_AVATAR))
        avatarFiles.push_back(VISTREAM_DEFAULT_AVATAR);
      else
        spdlog::info("no avatar model: {} is not there (give --avatar-model)",
                     VISTREAM_DEFAULT_AVATAR);
    } else if (avatarModels != std::vector<std::string>{"none"}) {
      for (const std::string& m : avatarModels) {
        if (!std::filesystem::exists(m)) throwInputError("--avatar-model {}: no such file", m);
        avatarFiles.push_back(m);
      }
    }
    worldOptions.pvsDatabase = pvsDb;
    if (!presence.empty()) {
      cfg.presence = parseRedisUrl(presence);
      if (!(cfg.avatarHz > 0.0))
        throwInputError("--presence needs avatar updates (--avatar-hz above 0): they publish it");
    }
    if (!httpPortFile.empty() && httpPort < 0)
      throwInputError("--http-port-file needs --http-port (0 picks a free one)");
    if (!worldOptions.impostorDatabase.empty() && pvsDb.empty())
      throwInputError("--impostor-db needs --pvs-db (the PVS database it was baked from)");
    if (!worldOptions.impostorDatabase.empty() &&
        !std::filesystem::exists(worldOptions.impostorDatabase))
      throwInputError("--impostor-db {}: no such file", worldOptions.impostorDatabase.string());
    worldOptions.fusion = *parseFusionChoice(fusion);
    worldOptions.lighting = !noLighting;
    StreamWorld world(openScene(scene, sceneLimits), worldOptions);
    cfg.avatarModels = std::make_shared<const AvatarCatalogue>(
        AvatarCatalogue::load(avatarFiles, avatarHeight, world.scene()));
    if (httpPort >= 0) cfg.httpPort = uint16_t(httpPort);
    StreamServer server(world, cfg);
    server.start();
    auto writePort = [](const std::string& file, uint16_t port) {
      writeFileAtomically(file, fmt::format("{}\n", port));
    };
    if (!portFile.empty()) writePort(portFile, server.port());
    if (!httpPortFile.empty()) writePort(httpPortFile, server.httpPort());
    server.run(true);
    return 0;
  });
}

}  // namespace vistream
