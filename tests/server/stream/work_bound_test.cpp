// Work a client can queue on the shared worker pool is bounded: on city1,
// where a cell's PVS costs milliseconds, clients that teleport or pile up
// requests leave nothing behind when they move on, leave or the server
// stops. Slow (city1's world takes seconds to build): label slow.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <random>

#include "common/generate/generate.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

using namespace std::chrono_literals;

// city1 (21,000 faces, PVS computed on demand): a cell's PVS costs enough
// that queued work shows.
struct CityServer {
  explicit CityServer(StreamServerConfig cfg = {}) : server(cfg, toScene(generate("city1"))) {}
  ServerFixture server;
  glm::dvec3 streetPoint() {
    // A cell centre on the free space grid the world built.
    const ViewCellGrid& g = server.world().grid();
    return glm::dvec3(g.cellBox(g.dims() / 2).center());
  }
  // Positions spread over the whole grid, far apart, a different one each call.
  glm::dvec3 randomPoint(std::mt19937& rng) {
    const ViewCellGrid& g = server.world().grid();
    std::uniform_int_distribution<int> x(0, g.dims().x - 1), z(0, g.dims().z - 1);
    return glm::dvec3(g.cellBox({x(rng), 0, z(rng)}).center());
  }
};

TEST(WorkBound, TeleportingClientsLeaveNoQueuedWorkBehindAndHonestClientsAreServed) {
  CityServer city;
  const uint16_t port = city.server.port();
  std::mt19937 rng(7);
  constexpr int kAttackers = 4, kPoses = 40;
  {
    std::vector<std::unique_ptr<TestClient>> attackers;
    for (int i = 0; i < kAttackers; ++i) {
      attackers.push_back(std::make_unique<TestClient>(port));
      attackers.back()->hello();
      ASSERT_TRUE(attackers.back()->nextOf(wire::Payload::Welcome));
    }
    // Every pose teleports across the city: each once queued up to nine
    // PVS computations on the shared pool.
    for (int p = 0; p < kPoses; ++p)
      for (auto& a : attackers) a->pose(city.randomPoint(rng), 0.0f, glm::vec3(1.4f, 0.0f, 0.0f));
    // An honest client is served while the attackers are still connected.
    EXPECT_TRUE(honestClientLoads(port, city.streetPoint(), 60.0));
  }  // the attackers leave: what they queued is cancelled
  EXPECT_TRUE(honestClientLoads(port, city.streetPoint() + glm::dvec3(40.0, 0.0, 0.0), 60.0));
  const auto stats = city.server.world().cacheStats();
  // Without bounds: ~9 computations per pose (1,440). With them, at most the
  // few that had started when each pose moved on, and the cancelled rest.
  EXPECT_LE(stats.pvsComputed, uint64_t(kAttackers * kPoses) / 2)
      << stats.pvsComputed << " PVS computed";
  std::printf("teleport attack: %llu PVS computed, %llu cancelled unstarted\n",
              (unsigned long long)stats.pvsComputed, (unsigned long long)stats.cancelled);
  EXPECT_GT(stats.cancelled, 0u);
}

// The attack as it was reported: ten connections sending ten teleporting
// poses a second for ten seconds, five honest clients loading during it and
// five after. Unbounded, this queued ~8,700 PVS computations, kept both
// cores busy for a minute after the attackers left and loaded none of the
// honest clients.
TEST(WorkBound, TenTeleportingClientsForTenSecondsStarveNoHonestClient) {
  CityServer city;
  const uint16_t port = city.server.port();
  constexpr int kAttackers = 10, kSeconds = 10, kHz = 10;
  std::atomic<int> poses{0};
  std::vector<std::thread> attackers;
  for (int i = 0; i < kAttackers; ++i)
    attackers.emplace_back([&, i] {
      std::mt19937 rng(uint32_t(100 + i));
      TestClient a(port);
      a.hello();
      if (!a.nextOf(wire::Payload::Welcome)) return;
      for (int p = 0; p < kSeconds * kHz; ++p) {
        a.pose(city.randomPoint(rng), 0.0f, glm::vec3(1.4f, 0.0f, 0.0f));
        ++poses;
        std::this_thread::sleep_for(std::chrono::milliseconds(1000 / kHz));
      }
    });
  int loadedDuring = 0, loadedAfter = 0;
  for (int h = 0; h < 5; ++h) {
    loadedDuring +=
        honestClientLoads(port, city.streetPoint() + glm::dvec3(4.0 * h, 0.0, 0.0), 10.0);
    std::this_thread::sleep_for(1s);
  }
  for (auto& t : attackers) t.join();
  const auto left = std::chrono::steady_clock::now();
  const auto atLeave = city.server.world().cacheStats();
  for (int h = 0; h < 5; ++h)
    loadedAfter +=
        honestClientLoads(port, city.streetPoint() - glm::dvec3(4.0 * h, 0.0, 8.0), 10.0);
  const double afterS =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - left).count();
  const auto end = city.server.world().cacheStats();
  std::printf(
      "%d teleporting poses: %llu PVS computed during the attack, %llu cancelled unstarted; "
      "%d of 5 honest clients loaded during it, %d of 5 after (all five in %.1f s after the "
      "attackers left, "
      "%llu more PVS computed meanwhile)\n",
      poses.load(), (unsigned long long)atLeave.pvsComputed, (unsigned long long)atLeave.cancelled,
      loadedDuring, loadedAfter, afterS,
      (unsigned long long)(end.pvsComputed - atLeave.pvsComputed));
  EXPECT_EQ(loadedDuring, 5);
  EXPECT_EQ(loadedAfter, 5);
  EXPECT_GT(atLeave.cancelled, 0u);
  // Nothing of the attack is left to compute once the attackers are gone:
  // after they left, only the honest clients' own cells (at most nine each)
  // and the two computations already running. Unbounded, thousands waited.
  EXPECT_LE(end.pvsComputed - atLeave.pvsComputed, uint64_t(5 * 9 + 2));
}

TEST(WorkBound, StoppingTheServerDropsQueuedVisibilityWork) {
  CityServer city;
  const uint16_t port = city.server.port();
  std::mt19937 rng(11);
  std::vector<std::unique_ptr<TestClient>> clients;
  for (int i = 0; i < 4; ++i) {
    clients.push_back(std::make_unique<TestClient>(port));
    clients.back()->hello();
    ASSERT_TRUE(clients.back()->nextOf(wire::Payload::Welcome));
  }
  // 40 PvsRequests for distinct cells from each client, all at once.
  for (auto& c : clients)
    for (int r = 0; r < 40; ++r) {
      wire::PvsRequestT q;
      q.request_id = uint32_t(r);
      q.by_cell = true;
      q.cell = std::make_unique<wire::CellIndex>(
          wire::toWire(*city.server.world().cellOf(glm::vec3(city.randomPoint(rng)))));
      c->sendRaw(wire::encodeMessage(std::move(q)));
    }
  std::this_thread::sleep_for(300ms);
  const uint64_t atStop = city.server.world().cacheStats().pvsComputed;
  city.server.shutDown();  // returns once the computations already running end
  const uint64_t after = city.server.world().cacheStats().pvsComputed;
  // Of 160 requests, only those running when the stop came (two workers)
  // and a few finishing as it spread may complete afterwards.
  EXPECT_LE(after - atStop, 8u) << atStop << " computed before the stop, " << after << " after";
  std::printf("stop: %llu PVS computed before the stop, %llu after\n", (unsigned long long)atStop,
              (unsigned long long)after);
  for (auto& c : clients) EXPECT_TRUE(c->closedWithin(5.0));
}

// SIGTERM under load, as an operator stops a busy server: the run ends, and
// what waited for a worker is abandoned rather than computed first (only
// the computations running when the signal came may still finish).
TEST(WorkBound, ASignalStopsABusyServerAndAbandonsTheWorkWaiting) {
  StreamWorld world(toScene(generate("city1")), StreamWorldOptions{});
  StreamServerConfig cfg;
  cfg.port = 0;
  cfg.workerThreads = 2;
  cfg.maxPvsRequestsInFlight = 64;  // every request reaches the queue at once
  StreamServer server(world, cfg);
  server.start();
  std::thread run([&] { server.run(true); });
  const ViewCellGrid& g = world.grid();
  std::mt19937 rng(13);
  std::uniform_int_distribution<int> x(0, g.dims().x - 1), z(0, g.dims().z - 1);
  std::vector<std::unique_ptr<TestClient>> clients;
  for (int i = 0; i < 4; ++i) {
    clients.push_back(std::make_unique<TestClient>(server.port()));
    clients.back()->hello();
    // Served: the signal handler is installed (run() sets it up before serving).
    ASSERT_TRUE(clients.back()->nextOf(wire::Payload::Welcome));
  }
  for (auto& c : clients)
    for (int r = 0; r < 100; ++r) {
      wire::PvsRequestT q;
      q.request_id = uint32_t(r);
      q.by_cell = true;
      q.cell = std::make_unique<wire::CellIndex>(wire::toWire(glm::ivec3(x(rng), 0, z(rng))));
      c->sendRaw(wire::encodeMessage(std::move(q)));
    }
  // Wait (bounded) until work waits for the workers.
  for (int i = 0; i < 500 && world.work().load().waiting < 50; ++i)
    std::this_thread::sleep_for(10ms);
  const size_t waiting = world.work().load().waiting;
  ASSERT_GE(waiting, 50u) << "no load to stop under";
  const uint64_t atSignal = world.cacheStats().pvsComputed;
  ASSERT_EQ(::kill(::getpid(), SIGTERM), 0);
  run.join();  // run() returns: the signal stopped the server
  for (auto& c : clients) EXPECT_TRUE(c->closedWithin(5.0));
  const uint64_t atReturn = world.cacheStats().pvsComputed;
  EXPECT_EQ(world.work().load().waiting, 0u) << "the waiting work was abandoned";
  // At most what was running (two workers) and what started before the
  // handler ran; never the waiting crowd.
  EXPECT_LT(atReturn - atSignal, uint64_t(waiting) / 4)
      << atSignal << " computed at the signal, " << atReturn << " when run() returned, " << waiting
      << " waiting";
  std::printf("signal: %zu computations waiting, %llu computed before, %llu more after\n", waiting,
              (unsigned long long)atSignal, (unsigned long long)(atReturn - atSignal));
}

}  // namespace
}  // namespace vistream::testing
