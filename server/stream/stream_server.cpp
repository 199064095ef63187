#include "server/stream/stream_server.h"

#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <boost/asio/bind_executor.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <cerrno>
#include <unordered_map>

#include "common/core/error.h"
#include "protocol/wire/messages.h"
#include "server/stream/http_endpoint.h"
#include "server/stream/session.h"
#include "server/visibility/pvs_database.h"

namespace vistream {

namespace asio = boost::asio;
using asio::ip::tcp;

namespace {
double processCpuMs() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return (double(u.ru_utime.tv_sec) + double(u.ru_stime.tv_sec)) * 1e3 +
         (double(u.ru_utime.tv_usec) + double(u.ru_stime.tv_usec)) * 1e-3;
}
}  // namespace

StreamServer::StreamServer(StreamWorld& world, StreamServerConfig config)
    : world_(world),
      config_(std::move(config)),
      workers_(config_.workerThreads ? config_.workerThreads
                                     : std::max(1u, std::thread::hardware_concurrency())),
      acceptor_(io_),
      avatarTimer_(io_),
      statsTimer_(io_),
      acceptStrand_(asio::make_strand(io_)),
      acceptRetryTimer_(acceptStrand_),
      maxClients_(config_.maxClients) {}

StreamServer::~StreamServer() {
  stop();
  workers_.join();
}

void StreamServer::abandonQueuedWork() {
  // Nothing waiting is started any more: what waits in the world's queue is
  // dropped, and so is what was posted to the pool (culling, encoding). The
  // workers finish what they are computing and end; join() waits for that.
  world_.abandonWork();
  workers_.stop();
}

void StreamServer::start() {
  boost::system::error_code ec;
  const auto address = asio::ip::make_address(config_.bindAddress, ec);
  if (ec) throwInputError("--bind {}: not an IP address", config_.bindAddress);
  const tcp::endpoint endpoint(address, config_.port);
  acceptor_.open(endpoint.protocol(), ec);
  if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor_.bind(endpoint, ec);
  if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    throwInputError("cannot listen on {}:{}: {}", config_.bindAddress, config_.port, ec.message());
  port_ = acceptor_.local_endpoint().port();
  fitOpenFileLimit();
  lastStats_ = std::chrono::steady_clock::now();
  lastCpuMs_ = processCpuMs();
  spdlog::info("vistream-server listening on {}:{} ({} policy{}, {} I/O threads)",
               config_.bindAddress, port_, streamPolicyName(config_.policy),
               config_.pvsOnly ? ", PVS only" : "", config_.ioThreads);
  if (config_.httpPort) {
    http_ = std::make_unique<HttpEndpoint>(*this, config_.bindAddress, *config_.httpPort);
    http_->start();
  }
  if (config_.presence) {
    if (!(config_.avatarHz > 0.0))
      throwInputError("--presence needs avatar updates (--avatar-hz above 0): they publish it");
    RedisPresence::Options po;
    po.redis = *config_.presence;
    po.sceneFingerprint = sceneFingerprint(world_.scene());
    po.staleAfterS = config_.presenceStaleS;
    presence_ = std::make_unique<RedisPresence>(po);
    idTag_ = uint32_t(presence_->replicaTag()) << 24;
  }
  accept();
  avatarTick();
  statsTick();
}

// Every session holds one descriptor, and the server needs a few of its own
// (listening socket, signal and timer plumbing, files, a rejected client's
// socket while its Error is written): without them accept() fails with
// EMFILE. Raise the soft limit as far as the hard one allows; what still
// does not fit lowers the maximum, and the log says so.
void StreamServer::fitOpenFileLimit() {
  constexpr rlim_t kReserve = 64;
  const rlim_t need = rlim_t(config_.maxClients) + kReserve;
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY ||
      limit.rlim_cur >= need)
    return;
  const rlim_t before = limit.rlim_cur;
  rlimit raised = limit;
  raised.rlim_cur = limit.rlim_max == RLIM_INFINITY ? need : std::min(need, limit.rlim_max);
  if (raised.rlim_cur > before && setrlimit(RLIMIT_NOFILE, &raised) == 0) limit = raised;
  if (limit.rlim_cur >= need) {
    spdlog::info("raised the open-file limit from {} to {} for --max-clients {}", before,
                 limit.rlim_cur, config_.maxClients);
    return;
  }
  maxClients_ = limit.rlim_cur > 2 * kReserve ? size_t(limit.rlim_cur - kReserve)
                                              : size_t(limit.rlim_cur / 2);
  spdlog::warn(
      "the open-file limit is {} (hard limit {}): --max-clients lowered from {} to {}",
      limit.rlim_cur,
      limit.rlim_max == RLIM_INFINITY ? std::string("none") : std::to_string(limit.rlim_max),
      config_.maxClients, maxClients_);
}

void StreamServer::accept() {
  acceptor_.async_accept(
      asio::make_strand(io_),
      asio::bind_executor(acceptStrand_, [this](const boost::system::error_code& ec,
                                                tcp::socket socket) {
        if (ec) {
          if (ec == asio::error::operation_aborted || stopping_ || !acceptor_.is_open()) return;
          // Out of descriptors: retrying at once would spin (and log) in a tight
          // loop until a session ends. Back off, 10 ms doubling to 1 s.
          // errno values compared directly: constructing error_conditions from
          // errc here trips UBSan's vptr check inside Boost 1.74.
          const int v = ec.value();
          const bool outOfDescriptors = ec.category() == boost::system::system_category() &&
                                        (v == EMFILE || v == ENFILE || v == ENOMEM || v == ENOBUFS);
          peerWarnings_.warn("accept: {}{}", ec.message(), outOfDescriptors ? "; backing off" : "");
          if (!outOfDescriptors) return accept();
          acceptBackoff_ = std::min<std::chrono::milliseconds>(
              std::chrono::seconds(1), std::max<std::chrono::milliseconds>(
                                           std::chrono::milliseconds(10), 2 * acceptBackoff_));
          acceptRetryTimer_.expires_after(acceptBackoff_);
          acceptRetryTimer_.async_wait(
              asio::bind_executor(acceptStrand_, [this](const boost::system::error_code& e) {
                if (!e && !stopping_) accept();
              }));
          return;
        }
        acceptBackoff_ = std::chrono::milliseconds(0);
        boost::system::error_code ignored;
        socket.set_option(tcp::no_delay(true), ignored);
        boost::system::error_code remoteError;
        const auto remote = socket.remote_endpoint(remoteError);
        if (remoteError) {  // gone before we looked: nothing to serve
          socket.close(ignored);
          if (!stopping_) accept();
          return;
        }
        const asio::ip::address address = remote.address();
        uint32_t id;
        std::string refusal;
        {
          std::lock_guard lock(sessionsMutex_);
          // With presence the replica tag fills the top 8 bits (unique
          // across replicas); the rest counts, skipping 0.
          if (idTag_ && (nextId_ & 0xFFFFFFu) == 0) ++nextId_;
          id = idTag_ ? idTag_ | (nextId_++ & 0xFFFFFFu) : nextId_++;
          if (stopping_) {
            refusal = "server is shutting down";
            ++rejectedStopping_;
          } else if (sessions_.size() >= maxClients_) {
            refusal = fmt::format("the server takes at most {} clients", maxClients_);
            ++rejectedFull_;
          } else if (config_.maxClientsPerAddress > 0 &&
                     perAddress_[address] >= config_.maxClientsPerAddress) {
            refusal = fmt::format("the server takes at most {} clients from one address",
                                  config_.maxClientsPerAddress);
            ++rejectedPerAddress_;
          }
          if (refusal.empty()) {
            ++perAddress_[address];
            addressOf_[id] = address;
          } else if (perAddress_.count(address) && perAddress_[address] == 0) {
            perAddress_.erase(address);
          }
        }
        auto session = std::make_shared<Session>(*this, std::move(socket), id);
        if (!refusal.empty()) {
          ++rejected_;
          session->reject(wire::ErrorCode::TooManyClients, refusal);
        } else {
          ++accepted_;
          {
            std::lock_guard lock(sessionsMutex_);
            sessions_[id] = session;
          }
          session->start();
        }
        if (!stopping_) accept();
      }));
}

void StreamServer::sessionEnded(uint32_t id, bool wasPlaced) {
  std::lock_guard lock(sessionsMutex_);
  if (sessions_.erase(id)) {
    ++ended_;
    // Only sessions others may have seen are announced, and only while
    // avatar updates run (they drain the list).
    if (wasPlaced && config_.avatarHz > 0.0) departed_.push_back(id);
  }
  if (auto it = addressOf_.find(id); it != addressOf_.end()) {
    if (--perAddress_[it->second] == 0) perAddress_.erase(it->second);
    addressOf_.erase(it);
  }
}

size_t StreamServer::sessionCount() const {
  std::lock_guard lock(sessionsMutex_);
  return sessions_.size();
}

StreamServer::QueueDepths StreamServer::queueDepths() const {
  QueueDepths d;
  std::lock_guard lock(sessionsMutex_);
  for (auto& [id, weak] : sessions_)
    if (auto session = weak.lock()) {
      ++d.sessions;
      d.totalBytes += session->queuedBytes();
      d.maxBytes = std::max(d.maxBytes, session->queuedBytes());
    }
  return d;
}

uint16_t StreamServer::httpPort() const {
  return http_ ? http_->port() : 0;
}

StreamServer::Counters StreamServer::counters() const {
  return {accepted_,     rejected_,          ended_, bytesSent_, rejectedStopping_,
          rejectedFull_, rejectedPerAddress_};
}

void StreamServer::avatarTick() {
  if (stopping_ || config_.avatarHz <= 0.0) return;
  // One update at a time: behind workers skip ticks rather than pile them up.
  if (avatarsInFlight_.exchange(true)) return scheduleAvatarTick();
  std::vector<std::shared_ptr<Session>> live;
  std::vector<uint32_t> departed;
  {
    std::lock_guard lock(sessionsMutex_);
    for (auto& [id, weak] : sessions_)
      if (auto s = weak.lock()) live.push_back(std::move(s));
    departed.swap(departed_);
  }
  // Filtering is visibility work: on the worker pool.
  asio::post(workers_, [this, live = std::move(live), departed = std::move(departed)]() mutable {
    std::vector<Session::Snapshot> snaps;
    snaps.reserve(live.size());
    for (const auto& s : live) snaps.push_back(s->snapshot());
    const auto now = std::chrono::steady_clock::now();
    if (presence_) {
      // Ours out (placed users), the other replicas' in: candidates for
      // every receiver here, never receivers themselves.
      std::vector<PresenceUser> ours;
      for (const Session::Snapshot& x : snaps)
        if (x.active && x.hasPose)
          ours.push_back({x.id, x.position, x.yawDeg, x.pitchDeg, x.speedMps, x.gait,
                          float(std::chrono::duration<double>(now - x.gaitSince).count())});
      presence_->publish(std::move(ours));
      RedisPresence::Remote remote = presence_->remote();
      departed.insert(departed.end(), remote.departed.begin(), remote.departed.end());
      for (const PresenceUser& u : remote.users) {
        const std::optional<glm::ivec3> cell = world_.cellOf(glm::vec3(u.position));
        if (!cell) continue;
        Session::Snapshot y;
        y.id = u.id;
        y.active = y.hasPose = true;
        y.position = u.position;
        y.yawDeg = u.yawDeg;
        y.pitchDeg = u.pitchDeg;
        y.speedMps = u.speedMps;
        y.gait = u.gait;
        y.gaitSince = now - std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                std::chrono::duration<double>(u.phaseS));
        y.cell = *cell;
        snaps.push_back(y);
      }
    }
    std::vector<std::pair<double, size_t>> near;
    for (size_t i = 0; i < live.size(); ++i) {
      const Session::Snapshot& x = snaps[i];
      if (!x.active || !x.hasPose || !x.wantsAvatars) continue;
      // The nearest others within the radius, then the visible ones among them.
      near.clear();
      for (size_t j = 0; j < snaps.size(); ++j) {
        const Session::Snapshot& y = snaps[j];
        const double d = glm::length(y.position - x.position);
        if (i != j && y.active && y.hasPose && d <= double(x.radius)) near.emplace_back(d, j);
      }
      std::sort(near.begin(), near.end());
      wire::AvatarT message;
      message.departed = departed;
      for (const auto& [d, j] : near) {
        if (message.avatars.size() >= config_.maxAvatars) break;
        const Session::Snapshot& y = snaps[j];
        if (!world_.cellSeesCell(x.cell, y.cell)) continue;
        auto a = std::make_unique<wire::AvatarStateT>();
        a->session_id = y.id;
        a->position = std::make_unique<wire::Vec3d>(wire::toWire(y.position));
        a->yaw_deg = y.yawDeg;
        a->pitch_deg = y.pitchDeg;
        a->speed_mps = y.speedMps;
        a->gait = wire::AvatarGait(y.gait);
        a->phase_s = float(std::chrono::duration<double>(now - y.gaitSince).count());
        if (config_.avatarModels) a->model = config_.avatarModels->modelOf(y.id);
        message.avatars.push_back(std::move(a));
      }
      live[i]->deliverAvatars(
          std::make_shared<const std::vector<uint8_t>>(wire::encodeMessage(std::move(message))));
    }
    avatarsInFlight_ = false;
  });
  scheduleAvatarTick();
}

void StreamServer::scheduleAvatarTick() {
  avatarTimer_.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / config_.avatarHz)));
  avatarTimer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) avatarTick();
  });
}

void StreamServer::statsTick() {
  if (stopping_) return;
  const auto now = std::chrono::steady_clock::now();
  const double dt = std::chrono::duration<double>(now - lastStats_).count();
  const double cpu = processCpuMs();
  if (dt > 0.0) cpuMsPerS_ = (cpu - lastCpuMs_) / dt;
  sinceLog_ += dt;
  peerWarnings_.flush();
  if (sinceLog_ >= config_.statsIntervalS) {
    sinceLog_ = 0.0;
    const QueueDepths depths = queueDepths();
    const size_t sessions = depths.sessions, queueSum = depths.totalBytes,
                 queueMax = depths.maxBytes;
    const uint64_t bytes = bytesSent_;
    const auto cs = world_.cacheStats();
    const double hitRate =
        cs.hits + cs.misses ? double(cs.hits) / double(cs.hits + cs.misses) : 0.0;
    const WorkQueue::Load work = world_.work().load();
    spdlog::info(
        "stats: {} sessions, {:.1f} kB/s out, cache hit rate {:.1f}% ({} PVS computed ({} coarse), "
        "{} unculled sets, {} from the database, {} cancelled unstarted, {} dropped), queues "
        "{:.1f} kB total / {:.1f} kB max, workers {} (visibility jobs waiting: {}, {} for current "
        "cells, the oldest for {:.1f} s), CPU {:.0f}%",
        sessions, double(bytes - lastBytes_) / 1e3 / config_.statsIntervalS, 100.0 * hitRate,
        cs.pvsComputed, cs.coarseComputed, cs.unculled, cs.pvsFromDatabase, cs.cancelled,
        cs.dropped, double(queueSum) / 1e3, double(queueMax) / 1e3,
        world_.work().behind(config_.behindLagS, config_.behindQueuedJobs) ? "behind"
                                                                           : "keeping up",
        work.waiting, work.waitingCurrent, work.oldestCurrentS, cpuMsPerS_ / 10.0);
    lastBytes_ = bytes;
  }
  lastStats_ = now;
  lastCpuMs_ = cpu;
  statsTimer_.expires_after(std::chrono::seconds(1));
  statsTimer_.async_wait([this](const boost::system::error_code& ec) {
    if (!ec) statsTick();
  });
}

void StreamServer::stop() {
  if (stopping_.exchange(true)) return;
  abandonQueuedWork();
  asio::post(acceptStrand_, [this] {
    boost::system::error_code ignored;
    acceptor_.close(ignored);
    if (http_) http_->stop();
    avatarTimer_.cancel();
    statsTimer_.cancel();
    acceptRetryTimer_.cancel();
    std::vector<std::shared_ptr<Session>> live;
    {
      std::lock_guard lock(sessionsMutex_);
      for (auto& [id, weak] : sessions_)
        if (auto s = weak.lock()) live.push_back(std::move(s));
    }
    for (auto& s : live) s->shutdown("server shutting down");
    // Give the Bye frames a moment, then end run().
    auto timer = std::make_shared<asio::steady_timer>(io_, std::chrono::milliseconds(300));
    timer->async_wait([this, timer](const boost::system::error_code&) { io_.stop(); });
  });
}

void StreamServer::run(bool handleSignals) {
  std::unique_ptr<asio::signal_set> signals;
  if (handleSignals) {
    signals = std::make_unique<asio::signal_set>(io_, SIGINT, SIGTERM);
    signals->async_wait([this](const boost::system::error_code& ec, int sig) {
      if (ec) return;
      spdlog::info("signal {}: shutting down", sig);
      stop();
    });
  }
  std::vector<std::thread> threads;
  for (unsigned i = 1; i < std::max(1u, config_.ioThreads); ++i)
    threads.emplace_back([this] { io_.run(); });
  io_.run();
  for (auto& t : threads) t.join();
  spdlog::info("vistream-server stopped: {} sessions served, {} rejected, {:.1f} MB sent",
               accepted_.load(), rejected_.load(), double(bytesSent_) / 1e6);
}

}  // namespace vistream
