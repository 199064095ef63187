// The streaming server: accepts TCP clients and streams to each what it can
// see (see protocol/README.md for the conversation).
//
// Threads: the io_context runs on `ioThreads` threads; every session does its
// socket work and state changes on its own strand, with one write in flight
// and a bounded send queue. Visibility work (PVS, face sets, culling,
// encoding geometry, avatar filtering) runs on a separate worker pool and
// posts its results back to the session's strand: I/O threads never compute.
//
// Bad input ends only the session that sent it: an Error frame where the
// socket still takes one, a log line, and the socket closed; every other
// session keeps being served. Memory per session is bounded by the inbound
// frame limit, the send queue limit and the client's memory budget.
#pragma once

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/thread_pool.hpp>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/core/log.h"
#include "server/stream/avatar_catalogue.h"
#include "server/stream/presence.h"
#include "server/stream/stream_scheduler.h"
#include "server/stream/stream_world.h"

namespace vistream {

struct StreamServerConfig {
  std::string bindAddress = "127.0.0.1";
  uint16_t port = 7070;  // 0: any free port (see StreamServer::port())
  unsigned ioThreads = 2;
  unsigned workerThreads = 0;  // 0: hardware concurrency
  size_t maxClients = 1000;
  std::string token;     // empty: no authentication
  bool pvsOnly = false;  // answer PvsRequest only, send no geometry
  StreamPolicy policy = StreamPolicy::Visibility;
  float defaultRadius = 200.0f;  // near-field radius when the client names none (metres)
  float maxRadius = 2000.0f;
  double maxClientKbps = 0.0;    // 0: unlimited
  double prefetchSeconds = 3.0;  // look-ahead along the client's velocity, and the
                                 // neighbour margin (this long at walking speed, at least 2 m)
  double avatarHz = 2.0;
  size_t maxAvatars = 16;  // nearest visible avatars per update
  // The models users are drawn as, offered in Welcome (null or empty: none;
  // Avatar updates still say where users are).
  std::shared_ptr<const AvatarCatalogue> avatarModels;
  // The HTTP port (http_endpoint.h: /healthz, /metrics, /pvs): nothing
  // for none, 0 for any free port (see StreamServer::httpPort()).
  std::optional<uint16_t> httpPort;
  // Shared presence with the other replicas through Redis (presence.h):
  // nothing for none. Needs avatar updates (avatarHz > 0), which publish it.
  std::optional<RedisAddress> presence;
  double presenceStaleS = 3.0;        // a replica silent this long has gone
  double statsIntervalS = 5.0;        // the server's log line
  double clientStatsIntervalS = 2.0;  // Stats frames to each client
  uint32_t maxInboundFrameBytes = 64u << 10;
  size_t sendQueueLimitBytes = 8u << 20;       // beyond this the client is not reading: closed
  size_t geometryWatermarkBytes = 256u << 10;  // produce geometry only below this queue depth
  size_t batchBytes = 48u << 10;               // raw face bytes per Geometry frame
  double helloTimeoutS = 5.0;
  double idleTimeoutS = 60.0;
  double writeStallTimeoutS = 20.0;
  unsigned maxFramesPerSecond = 400;
  double frameTimeoutS = 10.0;      // a frame must be whole this long after its first byte
  size_t maxClientsPerAddress = 0;  // sessions at once from one IP address (0: no limit; behind
                                    // a proxy every client has the proxy's address)
  // Plausible poses. A Pose faster than this, or farther than the margin
  // outside the scene's bounds, gets BadRequest naming the field.
  double maxSpeedMps = 100.0;
  double poseMarginM = 1000.0;
  // Visibility work a session may have outstanding on the shared worker
  // pool: cell face sets (the newest pose wins, stale ones are cancelled)
  // and PvsRequests (computed two at a time, a bounded number waiting).
  unsigned maxCellRequests = 3;
  unsigned maxPvsRequestsInFlight = 2;
  size_t maxPvsRequestsWaiting = 64;
  // The workers are behind when a current-cell computation has waited longer
  // than behindLagS or more than behindQueuedJobs current-cell computations
  // wait; then sessions stop asking for prefetch and refinement, and stop
  // culling (work_queue.h); without a database, cells without a cached set
  // get their unculled sets instead (stream_scheduler.h). Chosen on bigcity
  // without a database, 2 cores, 20 and 100 walking clients (a cell's face
  // set costs about 0.1 s there).
  double behindLagS = 0.5;
  size_t behindQueuedJobs = 4;
  // Sessions add no prefetch or refinement while more than this waits.
  size_t maxWaitingPrefetch = 8;
  // Without a database: seconds a client waits for its current cell's set
  // before it gets its block's unculled set (stream_scheduler.h).
  double unculledAfterS = StreamSchedulerConfig{}.unculledAfterS;
};

class Session;
class HttpEndpoint;

class StreamServer {
 public:
  StreamServer(StreamWorld& world, StreamServerConfig config);
  ~StreamServer();

  // Binds and starts accepting; throws InputError when the address is unusable.
  void start();
  // Runs until stop() (or SIGINT/SIGTERM when handleSignals is set).
  void run(bool handleSignals);
  // Stops accepting, abandons the visibility work waiting for a worker (the
  // world's queue and the pool's), says Bye to every session and ends run()
  // about 0.3 s later; the workers end once their current computations do.
  // Thread-safe. The world's queue stays abandoned: a world serves one
  // server's run.
  void stop();
  uint16_t port() const { return port_; }

  // For sessions.
  StreamWorld& world() { return world_; }
  const StreamServerConfig& config() const { return config_; }
  boost::asio::thread_pool& workers() { return workers_; }
  boost::asio::io_context& io() { return io_; }
  // A session ended; `wasPlaced` if it ever had a pose (others may have
  // seen its avatar, so its departure is announced).
  void sessionEnded(uint32_t id, bool wasPlaced);
  void countSent(size_t bytes) { bytesSent_ += bytes; }
  double cpuMsPerSecond() const { return cpuMsPerS_; }
  size_t sessionCount() const;
  // The limiter for warnings any peer can trigger (a refused or failed
  // session): a client that churns connections cannot flood the log.
  LogLimiter& peerWarnings() { return peerWarnings_; }
  // The configured maximum, or lower when the open-file limit does not
  // allow it (see start()).
  size_t maxClients() const { return maxClients_; }

  struct Counters {
    uint64_t accepted = 0, rejected = 0, ended = 0, bytesSent = 0;
    // rejected, by reason
    uint64_t rejectedStopping = 0, rejectedFull = 0, rejectedPerAddress = 0;
  };
  Counters counters() const;
  // The sessions' send queues now: summed and the deepest.
  struct QueueDepths {
    size_t sessions = 0, totalBytes = 0, maxBytes = 0;
  };
  QueueDepths queueDepths() const;
  bool stopping() const { return stopping_; }
  // The HTTP port listened on (after start()), 0 without one.
  uint16_t httpPort() const;
  // Shared presence (after start()), null without it.
  const RedisPresence* presence() const { return presence_.get(); }
  // The replica tag in the top 8 bits of every session ID (presence.h); 0
  // without presence.
  uint8_t replicaTag() const { return uint8_t(idTag_ >> 24); }

 private:
  void fitOpenFileLimit();
  void accept();
  void avatarTick();
  void scheduleAvatarTick();
  void abandonQueuedWork();
  void statsTick();

  StreamWorld& world_;
  StreamServerConfig config_;
  boost::asio::io_context io_;
  boost::asio::thread_pool workers_;
  boost::asio::ip::tcp::acceptor acceptor_;
  boost::asio::steady_timer avatarTimer_, statsTimer_;
  // The accept chain, its retry timer and stop() run on this strand.
  boost::asio::strand<boost::asio::io_context::executor_type> acceptStrand_;
  boost::asio::steady_timer acceptRetryTimer_;
  uint16_t port_ = 0;
  size_t maxClients_ = 0;
  std::chrono::milliseconds acceptBackoff_{0};
  LogLimiter peerWarnings_{"session warning"};
  mutable std::mutex
      sessionsMutex_;  // guards sessions_, addressOf_, perAddress_, departed_, nextId_
  std::map<uint32_t, std::weak_ptr<Session>> sessions_;
  std::map<uint32_t, boost::asio::ip::address> addressOf_;
  std::map<boost::asio::ip::address, size_t> perAddress_;
  std::vector<uint32_t> departed_;  // sessions ended since the last avatar update
  uint32_t nextId_ = 1;
  std::atomic<bool> stopping_{false};
  std::atomic<bool> avatarsInFlight_{false};  // one avatar update on the workers at a time
  std::atomic<uint64_t> accepted_{0}, rejected_{0}, ended_{0}, bytesSent_{0};
  std::atomic<uint64_t> rejectedStopping_{0}, rejectedFull_{0}, rejectedPerAddress_{0};
  std::unique_ptr<HttpEndpoint> http_;
  std::unique_ptr<RedisPresence> presence_;
  uint32_t idTag_ = 0;  // the replica tag << 24 (presence), or 0
  uint64_t lastBytes_ = 0;
  double lastCpuMs_ = 0.0, sinceLog_ = 0.0;
  std::atomic<double> cpuMsPerS_{0.0};
  std::chrono::steady_clock::time_point lastStats_;
};

}  // namespace vistream
