#include "client/loadtest/load_test.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <bit>
#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <thread>

#include "common/core/error.h"
#include "common/core/ivec_less.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "common/world/sealed_surface.h"
#include "common/world/solids.h"
#include "protocol/geometry/byte_coding.h"
#include "protocol/geometry/geometry_codec.h"
#include "protocol/wire/peer.h"

namespace vistream {

namespace asio = boost::asio;
using asio::ip::tcp;
using Clock = std::chrono::steady_clock;
using namespace wire;

namespace {

double msSince(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

nlohmann::json percentiles(std::vector<double> v) {
  if (v.empty())
    return {{"p50", nullptr}, {"p95", nullptr}, {"p99", nullptr}, {"max", nullptr}, {"count", 0}};
  std::sort(v.begin(), v.end());
  auto at = [&](double q) {
    return v[std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5))];
  };
  return {{"p50", at(0.5)},
          {"p95", at(0.95)},
          {"p99", at(0.99)},
          {"max", v.back()},
          {"count", v.size()}};
}

// Where the byte breakdown counts payload types newer than this build.
constexpr size_t kUnknownType = size_t(Payload::MAX) + 1;

struct Shared {
  const LoadTestOptions& options;
  std::unique_ptr<RayQuery> rays;
  FlatTriangles triangles;
  tcp::endpoint endpoint;
};

struct PathPoint {
  glm::dvec3 position;
  glm::dvec3 velocity;
  double yaw, pitch;
};
// Where a path puts the walker at path time t, and its velocity. Past the
// end the walker turns round and walks back (and so on), so a long test never
// teleports.
PathPoint pointAt(const std::vector<PathSample>& path, double t) {
  if (path.size() == 1)
    return {path[0].position, glm::dvec3(0.0), path[0].yawDeg, path[0].pitchDeg};
  const double t0 = path.front().t, span = path.back().t - t0;
  double local = t0;
  bool back = false;
  if (span > 0.0) {
    const double m = std::fmod(std::max(0.0, t), 2.0 * span);
    back = m > span;
    local = t0 + (back ? 2.0 * span - m : m);
  }
  size_t k = size_t(std::upper_bound(path.begin(), path.end(), local,
                                     [](double v, const PathSample& s) { return v < s.t; }) -
                    path.begin());
  k = std::clamp<size_t>(k, 1, path.size() - 1);
  const PathSample &a = path[k - 1], &b = path[k];
  const double dt = b.t - a.t;
  const double u = dt > 0.0 ? std::clamp((local - a.t) / dt, 0.0, 1.0) : 0.0;
  const double dyaw = std::remainder(b.yawDeg - a.yawDeg, 360.0);
  const glm::dvec3 v = dt > 0.0 ? (b.position - a.position) / dt : glm::dvec3(0.0);
  return {glm::mix(a.position, b.position, u), back ? -v : v,
          a.yawDeg + u * dyaw + (back ? 180.0 : 0.0), glm::mix(a.pitchDeg, b.pitchDeg, u)};
}

// One simulated client: a wire::Peer (protocol/wire/peer.h) for the
// connection, a timer on the peer's strand for the walk. Every handler runs on
// that strand.
class SimClient : public PeerHandler, public std::enable_shared_from_this<SimClient> {
 public:
  SimClient(asio::io_context& io, Shared& shared, size_t index)
      : shared_(shared),
        opt_(shared.options),
        index_(index),
        strand_(asio::make_strand(io)),
        peer_(Peer::create(strand_, kPeerOptions)),
        timer_(strand_),
        reconnectTimer_(strand_) {
    path_ = &opt_.paths[opt_.paths.size() == 1 ? 0 : index % opt_.paths.size()];
    const double span = path_->back().t - path_->front().t;
    offset_ = opt_.paths.size() == 1 && opt_.clients > 0
                  ? span * double(index) / double(opt_.clients)
                  : 0.0;
  }

  void start() {
    asio::dispatch(strand_, [self = shared_from_this()] {
      self->connectStarted_ = Clock::now();
      // One timeout for the connect and the Welcome; tick() replaces it.
      self->timer_.expires_after(std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(self->opt_.connectTimeoutS)));
      self->timer_.async_wait([self](const boost::system::error_code& ec) {
        if (ec || self->welcomed_) return;
        if (!self->connected_)
          return self->finish(
              fmt::format("connect timed out after {:g} s", self->opt_.connectTimeoutS), "connect");
        self->finish(
            fmt::format("no Welcome within {:g} s of connecting", self->opt_.connectTimeoutS),
            "handshake");
      });
      self->connect();
    });
  }

  // Opens a connection and says Hello: the first, or after the server
  // went away (then naming the faces still held, so that the server, this
  // one or another replica, sends only what is missing).
  void connect() {
    peer_->socket().async_connect(
        shared_.endpoint, [self = shared_from_this()](const boost::system::error_code& ec) {
          if (self->done_) return;
          if (ec) {
            if (self->reconnecting_) return self->retryLater();
            return self->finish("connect: " + ec.message(), "connect");
          }
          self->connected_ = true;
          boost::system::error_code ignored;
          self->peer_->socket().set_option(tcp::no_delay(true), ignored);
          self->peer_->start(self->weak_from_this());
          HelloT hello;
          hello.protocol_version = kProtocolVersion;
          hello.auth_token = self->opt_.token;
          hello.client_name = "vistream-loadtest";
          hello.capabilities = std::make_unique<CapabilitiesT>();
          hello.capabilities->near_field_radius_m = self->opt_.radius;
          hello.capabilities->memory_budget_bytes = self->opt_.memoryBudget;
          hello.capabilities->wants_avatars = self->opt_.avatars;
          hello.capabilities->stats_interval_s = self->opt_.statsIntervalS;
          if (self->reconnecting_) self->nameHeldFaces(hello);
          if (!self->reconnecting_) self->helloSent_ = Clock::now();
          self->send(encodeMessage(std::move(hello)));
        });
  }

  // The faces held, as Hello.held_faces; as many as fit the server's
  // inbound frame limit (the rest are sent again).
  void nameHeldFaces(HelloT& hello) {
    std::vector<uint32_t> faces;
    for (size_t w = 0; w < held_.size(); ++w)
      for (uint64_t bits = held_[w]; bits; bits &= bits - 1)
        faces.push_back(uint32_t(w * 64 + size_t(std::countr_zero(bits))));
    hello.held_scene_id = sceneId_;
    hello.held_face_count = grid_.faceCount;
    hello.held_faces = idRangesWithin(faces, kMaxHeldFacesBytes);
  }

  // The server went away while walking: reconnect (with backoff) through
  // the same address, where a proxy may hand us to another replica.
  void lost(const std::string& why) {
    if (done_) return;
    // Refused again before a Welcome (a proxy whose replica is down): retry.
    if (reconnecting_ && !welcomed_ && !walkEnded_) return retryLater();
    if (!opt_.reconnect || walkEnded_ || !welcomed_) return endedByServer(why);
    spdlog::debug("client {}: {}; reconnecting", index_, why);
    ++reconnects;
    reconnecting_ = true;
    welcomed_ = connected_ = false;
    lostAt_ = Clock::now();
    awaitingReload_ = true;
    backoff_ = std::chrono::milliseconds(100);
    retryLater();  // closes the connection
  }
  void endedByServer(const std::string& why) { finish(why, walkEnded_ ? "" : "closed_by_server"); }
  void retryLater() {
    // Jittered so that a replica's clients do not all come back at once.
    const auto wait = backoff_ + std::chrono::milliseconds((index_ * 37) % 100);
    backoff_ = std::min(backoff_ * 2, std::chrono::milliseconds(2000));
    peer_->close();
    peer_ = newPeer();
    connected_ = false;
    reconnectTimer_.expires_after(wait);
    reconnectTimer_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
      if (!ec && !self->done_) self->connect();
    });
  }

  // Called from any thread once the run's deadline has passed: closes the
  // connection; a client still connecting or walking is counted as cut off,
  // one already saying Bye finishes cleanly.
  void cutOffAtDeadline() {
    asio::post(strand_, [self = shared_from_this()] {
      if (self->done_) return;
      if (self->walkEnded_) return self->finish("", "");
      self->cutOff = true;
      const char* stage = self->reconnecting_ && !self->welcomed_ ? "reconnecting"
                          : !self->connected_                     ? "connecting"
                          : !self->welcomed_                      ? "waiting for the Welcome"
                                                                  : "walking";
      self->finish(fmt::format("cut off at the deadline while {}", stage), "cut_off");
    });
  }

  // Results, read after the io_context has stopped.
  uint64_t bytesReceived() const { return bytesBefore_ + peer_->bytesReceived(); }
  // Whole frames received, by payload type (index: wire::Payload; types
  // newer than this build at kUnknownType): bytes with their length prefixes.
  std::array<uint64_t, kUnknownType + 1> bytesByType{}, framesByType{};
  std::string errorReason;  // the first error's kind (a key of errors_by_reason); empty: none
  bool cutOff = false;
  uint64_t missesWhilePending = 0;
  std::vector<Hit> scratch_;  // seenTriangle's
  uint64_t misses = 0, checks = 0, geometryFrames = 0, facesReceived = 0, cellEntries = 0;
  uint64_t lightingBytes = 0;  // Geometry.lighting: the colours' share of Geometry bytes
  // Cell entries that found their cell ready, and the waits of those that
  // did not (entry to CellReady, or to the end of the walk if it never came).
  uint64_t cellEntriesReady = 0;
  std::vector<double> waits;
  std::vector<double> latencies;  // every entry: 0 for those found ready, then the waits
  double initialLoadMs = -1.0;
  std::vector<double> cpuPerClient;
  double walkedS = 0.0;
  std::string firstError;
  // Failover: connections lost while walking and made again; from a loss to
  // the new Welcome, and to the CellReady of the cell the client then stands in.
  uint64_t reconnects = 0, missesAfterReconnect = 0;
  std::vector<double> failoverMs, failoverReadyMs;
  // Other users seen (Avatar updates), and those of them on another replica
  // than this client's (the replica tag: the top 8 bits of session IDs).
  std::set<uint32_t> avatarsSeen, avatarsSeenOtherReplica;
  uint32_t firstSession = 0, lastSession = 0;

 private:
  static constexpr PeerOptions kPeerOptions{.maxFrameBytes = 64u << 20};

  std::shared_ptr<Peer> newPeer() {
    if (peer_) bytesBefore_ += peer_->bytesReceived();
    return Peer::create(strand_, kPeerOptions);
  }

  void send(std::vector<uint8_t> frame) {
    if (!done_ && connected_) peer_->send(std::move(frame));
  }

  void onPeerEnd(PeerEnd why, const std::string& text) override {
    switch (why) {
      case PeerEnd::ConnectionLost:
        return lost("connection closed by the server: " + text);
      case PeerEnd::BadFrame:
        return finish("bad frame from the server: " + text, "bad_frame");
      case PeerEnd::WriteFailed:
        return finish("write: " + text, "write");
      case PeerEnd::OutboxFull:
        return finish("the server is not reading: " + text, "write");
    }
  }

  void onFrame(const Envelope& e) override {
    if (done_) return;
    const size_t type = std::min(size_t(e.payload_type()), kUnknownType);
    bytesByType[type] += peer_->frameBytes();
    ++framesByType[type];
    dispatchPayload(
        e, Overloaded{
               [this](const Welcome& w) { onWelcome(w); },
               [this](const Geometry& g) { onGeometry(g); },
               [this](const Evict& evict) { onEvict(evict); },
               [this](const CellReady& r) { onCellReady(r); },
               [this](const Stats& s) {
                 if (s.sessions() > 0)
                   cpuPerClient.push_back(s.server_cpu_ms_per_s() / double(s.sessions()));
               },
               [this](const Error& err) {
                 finish(fmt::format("server error {}: {}", EnumNameErrorCode(err.code()),
                                    err.text() ? err.text()->str() : ""),
                        "server_error");
               },
               [this](const Bye&) { lost("server said bye"); },
               [this](const Avatar& a) { onAvatar(a); }, [](Payload) {},  // PvsReply: not measured
           });
  }

  void onWelcome(const Welcome& w) {
    // A second Welcome would restart the walk (and so its end): refused.
    if (welcomed_) return finish("a second Welcome", "protocol");
    WelcomeGrid grid;
    try {
      grid = validateWelcome(w);
    } catch (const InputError& error) {
      return finish(std::string("Welcome without a usable grid: ") + error.what(), "handshake");
    }
    const std::string sceneId = w.scene_id() ? w.scene_id()->str() : "";
    lastSession = w.session_id();
    if (reconnecting_) {
      // Another server must serve the same scene; the walk goes on.
      if (sceneId != sceneId_ || grid.faceCount != grid_.faceCount)
        return finish(fmt::format("reconnected to scene '{}' ({} faces), not '{}' ({} faces)",
                                  sceneId, grid.faceCount, sceneId_, grid_.faceCount),
                      "protocol");
      welcomed_ = true;
      failoverMs.push_back(msSince(lostAt_, Clock::now()));
      ready_.clear();  // the new session announces its own cells
      pending_.clear();
      hasCell_ = false;  // the next pose's cell is the reload's
      return;
    }
    grid_ = grid;
    sceneId_ = sceneId;
    firstSession = lastSession;
    welcomed_ = true;
    origin_ = grid_.localOrigin;
    radius_ = grid_.radius;
    held_.assign((size_t(grid_.faceCount) + 63) / 64, 0);
    walkStarted_ = Clock::now();
    tick();
  }

  void onGeometry(const Geometry& geometry) {
    DecodedGeometry g;
    std::string error;
    if (!decodeGeometry(geometry, grid_.quantization, g, error)) return finish(error, "bad_frame");
    ++geometryFrames;
    if (const auto* lighting = geometry.lighting()) lightingBytes += lighting->size();
    for (uint32_t f : g.faces)
      if ((f >> 6) < held_.size()) {
        held_[f >> 6] |= uint64_t(1) << (f & 63);
        ++facesReceived;
      }
  }

  void onEvict(const Evict& evict) {
    if (const auto* ids = evict.face_ids())
      for (uint32_t f : *ids)
        if ((f >> 6) < held_.size()) held_[f >> 6] &= ~(uint64_t(1) << (f & 63));
    // Cells away from here may have lost faces; the server announces them again.
    for (auto it = ready_.begin(); it != ready_.end();)
      it = glm::all(glm::lessThanEqual(glm::abs(*it - cell_), glm::ivec3(1))) ? std::next(it)
                                                                              : ready_.erase(it);
  }

  void onAvatar(const Avatar& a) {
    if (const auto* avatars = a.avatars())
      for (const wire::AvatarState* s : *avatars) {
        avatarsSeen.insert(s->session_id());
        if ((s->session_id() >> 24) != (lastSession >> 24))
          avatarsSeenOtherReplica.insert(s->session_id());
      }
  }

  void onCellReady(const CellReady& r) {
    const auto now = Clock::now();
    for (const glm::ivec3& c : readyCells(r)) {
      ready_.insert(c);
      if (awaitingReload_ && welcomed_ && hasCell_ && c == cell_) {
        awaitingReload_ = false;
        failoverReadyMs.push_back(msSince(lostAt_, now));
      }
      if (initialLoadMs < 0.0 && hasCell_ && c == cell_) initialLoadMs = msSince(helloSent_, now);
      if (auto it = pending_.find(c); it != pending_.end()) {
        waits.push_back(msSince(it->second, now));
        latencies.push_back(waits.back());
        pending_.erase(it);
      }
    }
  }

  void tick() {
    if (done_) return;
    const auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - walkStarted_).count();
    if (elapsed >= opt_.durationS) {
      walkEnded_ = true;
      walkedS = elapsed;
      for (const auto& [c, t] : pending_) {
        waits.push_back(msSince(t, now));  // still waiting: counted as such
        latencies.push_back(waits.back());
      }
      pending_.clear();
      send(encodeBye("load test finished"));
      // Let the Bye go out, then close.
      timer_.expires_after(std::chrono::milliseconds(200));
      timer_.async_wait(
          [self = shared_from_this()](const boost::system::error_code&) { self->finish("", ""); });
      return;
    }
    const PathPoint p = pointAt(*path_, offset_ + elapsed * opt_.speed);
    const glm::dvec3 local = p.position - origin_;
    PoseT pose;
    pose.position = std::make_unique<Vec3d>(toWire(local));
    pose.yaw_deg = float(p.yaw);
    pose.pitch_deg = float(p.pitch);
    pose.velocity = std::make_unique<Vec3f>(toWire(glm::vec3(p.velocity * opt_.speed)));
    pose.client_time_s = elapsed;
    send(encodeMessage(std::move(pose)));

    const glm::ivec3 cell = grid_.cellOf(glm::vec3(local));
    if (!hasCell_ || cell != cell_) {
      cell_ = cell;
      const bool first = !hasCell_;
      hasCell_ = true;
      // The initial load is the first time the client stands in a cell it
      // holds whole: announced before it arrived (a cell it walked into
      // after its first one's CellReady came late), or later (onCellReady).
      const bool loadedBefore = initialLoadMs >= 0.0;
      if (!loadedBefore && ready_.count(cell)) initialLoadMs = msSince(helloSent_, now);
      if (!first && loadedBefore) {
        ++cellEntries;
        if (ready_.count(cell)) {
          ++cellEntriesReady;
          latencies.push_back(0.0);
        } else {
          // Re-entering a cell still awaited joins the first entry's wait.
          pending_.emplace(cell, now);
        }
      }
    }
    if (awaitingReload_ && welcomed_ && ready_.count(cell_)) {
      awaitingReload_ = false;
      failoverReadyMs.push_back(msSince(lostAt_, now));
    }
    ++frame_;
    // Not while the server is away or reloading: nobody could have sent
    // what is missing.
    if (shared_.rays && opt_.checkEvery > 0 && initialLoadMs >= 0.0 && !awaitingReload_ &&
        frame_ % opt_.checkEvery == 0)
      check(local, p.yaw, p.pitch);
    timer_.expires_after(
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / opt_.fps)));
    timer_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
      if (!ec) self->tick();
    });
  }

  void check(const glm::dvec3& eye, double yaw, double pitch) {
    ++checks;
    const glm::dvec3 f = viewDirection(yaw, pitch);
    glm::dvec3 r = glm::cross(f, glm::dvec3(0, 1, 0));
    r = glm::length(r) > 1e-9 ? glm::normalize(r) : glm::dvec3(1, 0, 0);
    const glm::dvec3 u = glm::cross(r, f);
    const double th = std::tan(30.0 * 3.14159265358979323846 / 180.0), tv = th * 0.75;
    std::set<uint32_t> missing;
    for (int y = 0; y < opt_.checkRaysY; ++y)
      for (int x = 0; x < opt_.checkRaysX; ++x) {
        const glm::dvec3 d = f + r * (th * ((x + 0.5) / (0.5 * opt_.checkRaysX) - 1.0)) +
                             u * (tv * ((y + 0.5) / (0.5 * opt_.checkRaysY) - 1.0));
        const Ray ray{glm::vec3(eye), glm::vec3(glm::normalize(d)), 0.0f, radius_};
        const Hit h = shared_.rays->firstHit(ray);
        if (!h.valid()) continue;
        const uint32_t tri = seenTriangle(*shared_.rays, ray, h, scratch_);
        if (tri == kNoHit) continue;  // the back of a face grazed along its edge
        const uint32_t face = shared_.triangles.faceIds[tri];
        if ((face >> 6) >= held_.size() || !((held_[face >> 6] >> (face & 63)) & 1u))
          missing.insert(face);
      }
    misses += missing.size();
    if (reconnects > 0) missesAfterReconnect += missing.size();
    if (!ready_.count(cell_)) missesWhilePending += missing.size();
    for (uint32_t face : missing)
      spdlog::debug(
          "client {}: miss face {} from {:.3f},{:.3f},{:.3f} (file) in cell {},{},{} "
          "[{:.3f},{:.3f},{:.3f} .. "
          "{:.3f},{:.3f},{:.3f}] ({})",
          index_, face, eye.x + origin_.x, eye.y + origin_.y, eye.z + origin_.z, cell_.x, cell_.y,
          cell_.z, grid_.gridOrigin.x + grid_.cellSize.x * float(cell_.x) + origin_.x,
          grid_.gridOrigin.y + grid_.cellSize.y * float(cell_.y) + origin_.y,
          grid_.gridOrigin.z + grid_.cellSize.z * float(cell_.z) + origin_.z,
          grid_.gridOrigin.x + grid_.cellSize.x * float(cell_.x + 1) + origin_.x,
          grid_.gridOrigin.y + grid_.cellSize.y * float(cell_.y + 1) + origin_.y,
          grid_.gridOrigin.z + grid_.cellSize.z * float(cell_.z + 1) + origin_.z,
          ready_.count(cell_) ? "cell ready" : "cell not ready yet");
  }

  // Ends the client, once. `reason` empty: a clean end; otherwise the kind
  // of error (see errors_by_reason in README.md) and `why` the message.
  void finish(const std::string& why, const char* reason) {
    if (done_) return;
    done_ = true;
    if (*reason) {
      errorReason = reason;
      firstError = why;
      spdlog::debug("client {}: {}", index_, why);
    }
    if (walkedS == 0.0 && walkStarted_ != Clock::time_point{})
      walkedS = std::chrono::duration<double>(Clock::now() - walkStarted_).count();
    peer_->close();
    timer_.cancel();
  }

  Shared& shared_;
  const LoadTestOptions& opt_;
  size_t index_;
  Peer::Strand strand_;
  uint64_t bytesBefore_ = 0;  // received over earlier connections
  std::shared_ptr<Peer> peer_;
  asio::steady_timer timer_, reconnectTimer_;
  bool reconnecting_ = false, awaitingReload_ = false;
  Clock::time_point lostAt_;
  std::chrono::milliseconds backoff_{100};
  std::string sceneId_;
  const std::vector<PathSample>* path_ = nullptr;
  double offset_ = 0.0;
  bool connected_ = false, welcomed_ = false, done_ = false, walkEnded_ = false, hasCell_ = false;
  Clock::time_point connectStarted_, helloSent_, walkStarted_;
  WelcomeGrid grid_;
  glm::dvec3 origin_{0.0};
  glm::ivec3 cell_{0};
  float radius_ = 0.0f;
  std::vector<uint64_t> held_;
  std::set<glm::ivec3, IvecLess> ready_;
  std::map<glm::ivec3, Clock::time_point, IvecLess> pending_;
  uint64_t frame_ = 0;
};

}  // namespace

LoadTestReport runLoadTest(const LoadTestOptions& options) {
  if (options.clients == 0)
    throwInputError(InputErrorCode::BadArgument, "--clients must be at least 1");
  if (options.paths.empty() || std::any_of(options.paths.begin(), options.paths.end(),
                                           [](const auto& p) { return p.empty(); }))
    throwInputError(InputErrorCode::BadArgument, "no path to walk");
  if (!(options.durationS > 0.0) || !(options.fps > 0.0) || !(options.speed >= 0.0) ||
      !std::isfinite(options.durationS) || !std::isfinite(options.speed))
    throwInputError(InputErrorCode::BadArgument,
                    "--duration and --fps must be positive and --speed non-negative");
  if (!(options.statsIntervalS >= 0.0f) || !std::isfinite(options.statsIntervalS))
    throwInputError(InputErrorCode::BadArgument, "--stats-interval must be zero or positive");
  if (!(options.connectTimeoutS > 0.0) || !std::isfinite(options.connectTimeoutS))
    throwInputError(InputErrorCode::BadArgument, "--connect-timeout must be positive");
  const double graceS =
      options.graceS.value_or(options.connectTimeoutS + kDefaultGraceBeyondConnectS);
  if (!(graceS >= 0.0) || !std::isfinite(graceS))
    throwInputError(InputErrorCode::BadArgument, "--grace must be zero or positive");
  Shared shared{options, nullptr, {}, {}};
  if (options.scene) {
    shared.triangles = flattenScene(*options.scene, true);
    // The miss check samples the surface the PVS is proved for: cracks
    // narrower than the weld tolerance closed (common/world/sealed_surface.h).
    shared.rays = makeSealedRayQuery(shared.triangles, SolidsOptions{}.weldTolerance);
  }
  asio::io_context io;
  {
    tcp::resolver resolver(io);
    boost::system::error_code ec;
    auto results = resolver.resolve(options.host, std::to_string(options.port), ec);
    if (ec || results.empty())
      throwInputError(InputErrorCode::Unreachable, "--host {}: cannot resolve it: {}", options.host,
                      ec.message());
    shared.endpoint = *results.begin();
  }
  const auto started = Clock::now();
  const auto deadline = started + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(options.durationS + graceS));
  std::vector<std::shared_ptr<SimClient>> clients;
  for (size_t i = 0; i < options.clients; ++i) {
    clients.push_back(std::make_shared<SimClient>(io, shared, i));
    clients.back()->start();
  }
  // Runs until every client has finished (the io_context runs out of work) or
  // the deadline, whichever comes first; then closes whatever is still open.
  // Closing cancels every pending operation, so the second run ends at once;
  // its own bound only guards against a handler that never returns control.
  std::vector<std::thread> threads;
  for (unsigned t = 1; t < std::max(1u, options.threads); ++t)
    threads.emplace_back([&io, deadline] { io.run_until(deadline); });
  io.run_until(deadline);
  for (auto& t : threads) t.join();
  io.restart();
  for (const auto& c : clients) c->cutOffAtDeadline();
  io.run_for(std::chrono::seconds(2));
  const double wall = std::chrono::duration<double>(Clock::now() - started).count();

  std::vector<double> latencies, waits, initial, cpu, bytesPerS, failover, failoverReady;
  uint64_t reconnects = 0, reconnected = 0, avatarsSeen = 0, avatarsOther = 0, seeingOther = 0,
           missesAfterReconnect = 0;
  std::map<std::string, uint64_t> byReplica, byReplicaAtEnd;
  uint64_t misses = 0, checks = 0, entries = 0, entriesReady = 0, frames = 0, faces = 0,
           lighting = 0, totalBytes = 0, pendingMisses = 0;
  size_t loaded = 0, failed = 0;
  std::string firstError, firstFailure;
  auto failedClients = nlohmann::json::array(), cutOffClients = nlohmann::json::array();
  std::map<std::string, uint64_t> byReason;
  // Bytes by payload type; what the clients received beyond whole frames
  // (a frame cut off when the connection closed) counts as "partial_frame",
  // so the breakdown sums to `bytes_received`.
  std::array<uint64_t, kUnknownType + 1> typeBytes{}, typeFrames{};
  uint64_t partialBytes = 0;
  for (size_t i = 0; i < clients.size(); ++i) {
    const SimClient* c = clients[i].get();
    uint64_t whole = 0;
    for (size_t t = 0; t <= kUnknownType; ++t) {
      typeBytes[t] += c->bytesByType[t];
      typeFrames[t] += c->framesByType[t];
      whole += c->bytesByType[t];
    }
    partialBytes += c->bytesReceived() - std::min(whole, c->bytesReceived());
    latencies.insert(latencies.end(), c->latencies.begin(), c->latencies.end());
    waits.insert(waits.end(), c->waits.begin(), c->waits.end());
    if (c->initialLoadMs >= 0.0) {
      initial.push_back(c->initialLoadMs);
      ++loaded;
    }
    // A client that ended cleanly without its initial load failed too: the
    // server served it nothing usable.
    std::string reason = c->errorReason, error = c->firstError;
    if (reason.empty() && c->initialLoadMs < 0.0) {
      reason = "not_loaded";
      error = fmt::format(
          "never received the CellReady of the cell it stood in ({:.1f} s of walking)", c->walkedS);
    }
    if (!reason.empty()) {
      ++failed;
      ++byReason[reason];
      failedClients.push_back({{"client", i}, {"reason", reason}, {"error", error}});
      if (firstError.empty()) {
        firstError = error;
        firstFailure = fmt::format("client {}: {}", i, error);
      }
    }
    if (c->cutOff) cutOffClients.push_back(i);
    cpu.insert(cpu.end(), c->cpuPerClient.begin(), c->cpuPerClient.end());
    bytesPerS.push_back(c->walkedS > 0.0 ? double(c->bytesReceived()) / c->walkedS : 0.0);
    misses += c->misses;
    reconnects += c->reconnects;
    reconnected += c->reconnects > 0;
    missesAfterReconnect += c->missesAfterReconnect;
    failover.insert(failover.end(), c->failoverMs.begin(), c->failoverMs.end());
    failoverReady.insert(failoverReady.end(), c->failoverReadyMs.begin(), c->failoverReadyMs.end());
    avatarsSeen += c->avatarsSeen.size();
    avatarsOther += c->avatarsSeenOtherReplica.size();
    seeingOther += !c->avatarsSeenOtherReplica.empty();
    if (c->firstSession) ++byReplica[std::to_string(c->firstSession >> 24)];
    if (c->lastSession) ++byReplicaAtEnd[std::to_string(c->lastSession >> 24)];
    pendingMisses += c->missesWhilePending;
    checks += c->checks;
    entries += c->cellEntries;
    entriesReady += c->cellEntriesReady;
    frames += c->geometryFrames;
    lighting += c->lightingBytes;
    faces += c->facesReceived;
    totalBytes += c->bytesReceived();
  }
  nlohmann::json bytesByType = nlohmann::json::object(), framesByType = nlohmann::json::object();
  for (size_t t = 0; t <= kUnknownType; ++t)
    if (typeFrames[t] > 0) {
      const char* name = t == kUnknownType ? "unknown" : payloadName(Payload(t));
      bytesByType[name] = typeBytes[t];
      framesByType[name] = typeFrames[t];
    }
  if (partialBytes > 0) bytesByType["partial_frame"] = partialBytes;
  double meanBytes = 0.0;
  for (double b : bytesPerS) meanBytes += b / double(bytesPerS.size());
  double cpuMean = 0.0;
  for (double v : cpu) cpuMean += v / double(cpu.size());
  LoadTestReport report;
  report.json = {{"clients", options.clients},
                 {"duration_s", options.durationS},
                 {"wall_s", wall},
                 {"speed", options.speed},
                 {"bytes_per_client_per_s", meanBytes},
                 {"cell_ready_latency_ms", percentiles(latencies)},
                 {"cell_entries", entries},
                 {"cell_entries_ready", entriesReady},
                 {"cell_entries_waited", entries - entriesReady},
                 {"cell_ready_wait_ms", percentiles(waits)},
                 {"visibility_misses", misses},
                 {"visibility_misses_cell_not_ready", pendingMisses},
                 {"frames_checked", checks},
                 {"initial_load_ms", percentiles(initial)},
                 {"clients_loaded", loaded},
                 {"clients_not_loaded", clients.size() - loaded},
                 {"clients_cut_off", cutOffClients.size()},
                 {"cut_off_clients", cutOffClients},
                 {"grace_s", graceS},
                 {"geometry_frames", frames},
                 {"faces_received", faces},
                 {"bytes_per_face", faces ? double(totalBytes) / double(faces) : 0.0},
                 {"geometry_bytes_per_face",
                  faces ? double(typeBytes[size_t(Payload::Geometry)]) / double(faces) : 0.0},
                 {"lighting_bytes_per_face", faces ? double(lighting) / double(faces) : 0.0},
                 {"bytes_received", totalBytes},
                 {"bytes_by_type", bytesByType},
                 {"frames_by_type", framesByType},
                 {"errors", failed},
                 {"errors_by_reason", byReason},
                 {"failed_clients", failedClients},
                 {"first_error", firstError},
                 {"reconnects", reconnects},
                 {"clients_reconnected", reconnected},
                 {"failover_ms", percentiles(failover)},
                 {"failover_ready_ms", percentiles(failoverReady)},
                 {"visibility_misses_after_reconnect", missesAfterReconnect},
                 {"avatars_seen", avatarsSeen},
                 {"avatars_seen_other_replica", avatarsOther},
                 {"clients_seeing_other_replica", seeingOther},
                 {"clients_by_replica", byReplica},
                 {"clients_by_replica_at_end", byReplicaAtEnd},
                 {"server_cpu_ms_per_s_per_client",
                  cpu.empty() ? nlohmann::json(nullptr) : nlohmann::json(cpuMean)}};
  if (failed > 0) {
    std::string reasons;
    for (const auto& [reason, n] : byReason)
      reasons += fmt::format("{}{} {}", reasons.empty() ? "" : ", ", reason, n);
    report.failure =
        fmt::format("{} of {} clients failed ({}); {} of {} got their initial load; first: {}",
                    failed, clients.size(), reasons, loaded, clients.size(), firstFailure);
  }
  return report;
}

}  // namespace vistream
