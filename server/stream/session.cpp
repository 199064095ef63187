#include "server/stream/session.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/bind_executor.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/write.hpp>
#include <cmath>

#include "protocol/geometry/byte_coding.h"
#include "protocol/geometry/geometry_codec.h"
#include "protocol/impostor/impostor_message.h"
#include "server/stream/stream_server.h"

namespace vistream {

namespace asio = boost::asio;
using namespace wire;

namespace {
double seconds(std::chrono::steady_clock::duration d) {
  return std::chrono::duration<double>(d).count();
}

bool sameToken(const std::string& a, const std::string& b) {
  // Constant time in the token's length.
  unsigned diff = unsigned(a.size() != b.size());
  for (size_t i = 0; i < a.size(); ++i)
    diff |= unsigned(uint8_t(a[i]) ^ uint8_t(i < b.size() ? b[i] : 0));
  return diff == 0;
}
}  // namespace

Session::Session(StreamServer& server, asio::ip::tcp::socket socket, uint32_t id)
    : server_(server),
      world_(server.world()),
      strand_(asio::make_strand(server.io())),
      socket_(std::move(socket)),
      housekeepingTimer_(strand_),
      id_(id),
      decoder_(server.config().maxInboundFrameBytes),
      outbox_(server.config().sendQueueLimitBytes) {}

Session::~Session() = default;

void Session::start() {
  asio::dispatch(strand_, [self = shared_from_this()] {
    self->started_ = self->lastInbound_ = self->windowStart_ = self->lastRefill_ = Clock::now();
    self->read();
    self->housekeeping();
  });
}

void Session::reject(ErrorCode code, const std::string& text) {
  asio::dispatch(strand_, [self = shared_from_this(), code, text] {
    self->started_ = Clock::now();
    self->fail(code, text);
    self->housekeeping();
  });
}

void Session::shutdown(const std::string& reason) {
  asio::dispatch(strand_, [self = shared_from_this(), reason] {
    if (self->state_ == State::Closed || self->state_ == State::Closing) return;
    self->cancelWork();
    // Closing before the send: a send over the queue limit closes at once,
    // and nothing may turn Closed back into Closing.
    self->state_ = State::Closing;
    self->closingSince_ = Clock::now();
    self->send(std::make_shared<const std::vector<uint8_t>>(encodeBye(reason)));
    if (self->state_ == State::Closing && self->outbox_.empty()) self->close("shutdown");
  });
}

void Session::deliverAvatars(std::shared_ptr<const std::vector<uint8_t>> frame) {
  asio::dispatch(strand_, [self = shared_from_this(), frame = std::move(frame)] {
    if (self->state_ == State::Active) self->send(frame);
  });
}

Session::Snapshot Session::snapshot() const {
  std::lock_guard lock(snapshotMutex_);
  return snapshot_;
}

void Session::read() {
  socket_.async_read_some(
      asio::buffer(readBuffer_),
      asio::bind_executor(
          strand_, [self = shared_from_this()](const boost::system::error_code& ec, size_t n) {
            if (self->state_ == State::Closed) return;
            if (ec) {
              if (self->decoder_.buffered() > 0)
                self->server_.peerWarnings().warn(
                    "session {}: connection lost in the middle of a frame ({} bytes buffered): {}",
                    self->id_, self->decoder_.buffered(), ec.message());
              self->close(ec == asio::error::eof ? "client closed the connection" : "read error");
              return;
            }
            self->onBytes(std::span<const uint8_t>(self->readBuffer_.data(), n));
            if (self->state_ == State::AwaitHello || self->state_ == State::Active) self->read();
          }));
}

void Session::onBytes(std::span<const uint8_t> bytes) {
  const auto errorCode = [this] { return wireErrorCode(decoder_.errorCode()); };
  if (!decoder_.feed(bytes)) return fail(errorCode(), decoder_.error());
  const auto now = Clock::now();
  unsigned frames = 0;
  while (state_ == State::AwaitHello || state_ == State::Active) {
    auto frame = decoder_.next();
    if (!frame) {
      if (decoder_.failed()) return fail(errorCode(), decoder_.error());
      break;
    }
    ++frames;
    lastInbound_ = now;  // the idle timeout counts whole frames, not bytes
    // Inbound rate limit over one-second windows.
    if (now - windowStart_ >= std::chrono::seconds(1)) {
      windowStart_ = now;
      framesInWindow_ = 0;
    }
    if (++framesInWindow_ > server_.config().maxFramesPerSecond)
      return fail(ErrorCode::RateLimited, fmt::format("more than {} frames per second",
                                                      server_.config().maxFramesPerSecond));
    onFrame(*envelopeOf(*frame));
  }
  // A frame has a deadline from its first byte (housekeeping checks it).
  if (frames > 0 || !midFrame_) frameStarted_ = now;
  midFrame_ = decoder_.buffered() > 0;
}

void Session::onFrame(const Envelope& envelope) {
  dispatchPayload(envelope,
                  Overloaded{
                      [this](const Hello& hello) { onHello(hello); },
                      [this](const Pose& pose) {
                        if (state_ != State::Active)
                          return fail(ErrorCode::OutOfOrder, "Pose before Hello");
                        onPose(pose);
                      },
                      [this](const PvsRequest& request) {
                        if (state_ != State::Active)
                          return fail(ErrorCode::OutOfOrder, "PvsRequest before Hello");
                        onPvsRequest(request);
                      },
                      [this](const AvatarModelRequest& request) {
                        if (state_ != State::Active)
                          return fail(ErrorCode::OutOfOrder, "AvatarModelRequest before Hello");
                        onAvatarModelRequest(request);
                      },
                      [this](const Bye&) {
                        spdlog::debug("session {}: client said bye", id_);
                        close("bye");
                      },
                      [this](const Error& e) {
                        server_.peerWarnings().warn("session {}: client reported error {}: {}", id_,
                                                    int(e.code()),
                                                    e.text() ? e.text()->str() : std::string());
                        close("client error");
                      },
                      [this](Payload type) {
                        if (type > Payload::MAX || type == Payload::NONE)
                          return fail(ErrorCode::MalformedFrame,
                                      fmt::format("unknown payload type {}", unsigned(type)));
                        fail(ErrorCode::OutOfOrder,
                             fmt::format("{} is a server-to-client message", payloadName(type)));
                      },
                  });
}

void Session::onHello(const Hello& hello) {
  const StreamServerConfig& cfg = server_.config();
  if (state_ != State::AwaitHello) return fail(ErrorCode::OutOfOrder, "second Hello");
  if (hello.protocol_version() != kProtocolVersion)
    return fail(ErrorCode::UnsupportedVersion,
                fmt::format("protocol version {} is not supported (server speaks {})",
                            hello.protocol_version(), kProtocolVersion));
  if (!cfg.token.empty() &&
      !sameToken(hello.auth_token() ? hello.auth_token()->str() : std::string(), cfg.token))
    return fail(ErrorCode::BadToken, "bad auth token");
  radius_ = cfg.defaultRadius;
  statsIntervalS_ = cfg.clientStatsIntervalS;
  if (const Capabilities* caps = hello.capabilities()) {
    const float r = caps->near_field_radius_m();
    if (!std::isfinite(r) || r < 0.0f)
      return fail(ErrorCode::BadRequest, "near_field_radius_m must be finite and >= 0");
    if (r > 0.0f) radius_ = std::min(r, cfg.maxRadius);
    const float statsInterval = caps->stats_interval_s();
    if (!std::isfinite(statsInterval) || statsInterval < 0.0f)
      return fail(ErrorCode::BadRequest, "stats_interval_s must be finite and >= 0");
    // Never more often than the server's own interval.
    statsIntervalS_ = std::max(cfg.clientStatsIntervalS, double(statsInterval));
    budget_ = caps->memory_budget_bytes();
    wantsGeometry_ = caps->wants_geometry();
    wantsAvatars_ = caps->wants_avatars();
    wantsImpostors_ = caps->wants_impostors() && world_.hasImpostors() && wantsGeometry_;
  }
  state_ = State::Active;
  StreamSchedulerConfig sc;
  sc.policy = cfg.policy;
  sc.prefetchSeconds = cfg.prefetchSeconds;
  sc.maxSpeedMps = cfg.maxSpeedMps;
  sc.maxCellRequests = cfg.maxCellRequests;
  sc.batchBytes = cfg.batchBytes;
  // Prefetch deltas gather into batches of about 100 city1 faces (8 bytes a
  // face after coding rather than 25 for 10) unless something is due.
  sc.coalesceBytes = std::min<size_t>(8u << 10, cfg.batchBytes);
  sc.coarseFirst = world_.coarseFirst();
  sc.unculledAfterS = cfg.unculledAfterS;
  sc.impostors = wantsImpostors_;
  scheduler_ = std::make_unique<StreamScheduler>(world_, sc, radius_, budget_);
  if (const auto* held = hello.held_faces(); held && held->size() > 0 && wantsGeometry_) {
    // A reconnecting client's faces count only for the scene they came from.
    const std::string heldScene = hello.held_scene_id() ? hello.held_scene_id()->str() : "";
    if (heldScene == world_.scene().name && hello.held_face_count() == world_.faceCount()) {
      PayloadReader reader({held->data(), held->size()});
      std::vector<uint32_t> faces;
      if (!readIdRanges(reader, world_.faceCount(), world_.faceCount(), "Hello.held_faces", faces))
        return fail(ErrorCode::BadRequest, reader.error());
      scheduler_->markHeld(faces);
      spdlog::debug("session {}: the client holds {} faces from an earlier session", id_,
                    faces.size());
    } else {
      spdlog::debug(
          "session {}: held faces of scene '{}' ({} faces) ignored: this is '{}' ({} faces)", id_,
          heldScene, hello.held_face_count(), world_.scene().name, world_.faceCount());
    }
  }
  {
    std::lock_guard lock(snapshotMutex_);
    snapshot_.id = id_;
    snapshot_.active = true;
    snapshot_.wantsAvatars = wantsAvatars_;
    snapshot_.radius = radius_;
  }
  const Scene& scene = world_.scene();
  WelcomeT w;
  w.protocol_version = kProtocolVersion;
  w.scene_id = scene.name;
  w.session_id = id_;
  const Box3f b = scene.bounds();
  w.bounds_min = std::make_unique<Vec3d>(toWire(glm::dvec3(b.lo)));
  w.bounds_max = std::make_unique<Vec3d>(toWire(glm::dvec3(b.hi)));
  w.local_origin = std::make_unique<Vec3d>(toWire(scene.origin));
  w.grid = std::make_unique<CellGridT>();
  w.grid->origin = std::make_unique<Vec3f>(toWire(world_.grid().origin()));
  w.grid->cell_size = std::make_unique<Vec3f>(toWire(world_.grid().cellSize()));
  w.grid->dims = std::make_unique<CellIndex>(toWire(world_.grid().dims()));
  for (const Material& m : scene.materials) {
    auto mi = std::make_unique<MaterialInfoT>();
    mi->name = m.name;
    mi->diffuse = std::make_unique<Vec3f>(toWire(m.diffuse));
    w.materials.push_back(std::move(mi));
  }
  w.environment_colour = std::make_unique<Vec3f>(toWire(scene.environment.skyColor));
  w.environment_map = scene.environment.hdrImage.string();
  w.face_count = world_.faceCount();
  w.near_field_radius_m = radius_;
  w.pvs_only = cfg.pvsOnly;
  w.policy = streamPolicyName(cfg.policy);
  if (const auto& g = world_.ground().y) {
    w.has_ground = true;
    w.ground_y = *g;
  }
  if (const auto& backdrop = world_.backdrop()) {
    w.sky_rgb = std::make_unique<Rgb8>(backdrop->sky.r, backdrop->sky.g, backdrop->sky.b);
    w.ground_rgb =
        std::make_unique<Rgb8>(backdrop->ground.r, backdrop->ground.g, backdrop->ground.b);
    w.haze_distance_m = backdrop->haze.scale;
  }
  const QuantizationGrid quantization = QuantizationGrid::forBounds(b);  // as every Geometry's
  w.quant_origin = std::make_unique<Vec3d>(toWire(quantization.origin));
  w.quant_step = quantization.step;
  w.impostors = wantsImpostors_;
  if (const auto& avatars = cfg.avatarModels; avatars && !avatars->models.empty()) {
    for (const ServedAvatarModel& m : avatars->models) {
      auto info = std::make_unique<AvatarModelInfoT>();
      info->name = m.name;
      info->bytes = m.bytes;
      info->height_m = m.heightM;
      w.avatar_models.push_back(std::move(info));
    }
    for (const glm::vec3& c : avatars->light.sky)
      w.avatar_light.insert(w.avatar_light.end(), {c.r, c.g, c.b});
    w.avatar_light.insert(w.avatar_light.end(), avatars->light.sun.begin(),
                          avatars->light.sun.end());
    if (glm::length(avatars->light.sunDirection) > 0.0f)
      w.avatar_sun_direction = std::make_unique<Vec3f>(toWire(avatars->light.sunDirection));
    modelsSent_.assign(avatars->models.size(), 0);
  }
  send(std::make_shared<const std::vector<uint8_t>>(encodeMessage(std::move(w))));
  spdlog::debug("session {}: welcome (radius {:.0f} m, budget {} bytes)", id_, radius_, budget_);
}

void Session::onPose(const Pose& pose) {
  const StreamServerConfig& cfg = server_.config();
  if (!isFinite(pose.position()) || !std::isfinite(pose.yaw_deg()) ||
      !std::isfinite(pose.pitch_deg()) || (pose.velocity() && !isFinite(pose.velocity())))
    return fail(ErrorCode::BadRequest,
                "Pose with a missing or non-finite position, orientation or velocity");
  // Plausibility: everything below samples the client's neighbourhood, so a
  // position far outside the scene or an absurd speed is refused outright.
  const glm::dvec3 p = fromWire(*pose.position());
  const Box3f bounds = world_.scene().bounds();
  const glm::dvec3 lo = glm::dvec3(bounds.lo) - cfg.poseMarginM,
                   hi = glm::dvec3(bounds.hi) + cfg.poseMarginM;
  if (bounds.empty() || glm::any(glm::lessThan(p, lo)) || glm::any(glm::greaterThan(p, hi)))
    return fail(ErrorCode::BadRequest, fmt::format("Pose.position ({:.6g}, {:.6g}, {:.6g}) lies "
                                                   "more than {:.0f} m outside the scene's bounds",
                                                   p.x, p.y, p.z, cfg.poseMarginM));
  const glm::vec3 v = pose.velocity() ? fromWire(*pose.velocity()) : glm::vec3(0.0f);
  const double speed = glm::length(glm::dvec3(v));  // in double: a float's square may overflow
  if (!(speed <= cfg.maxSpeedMps))
    return fail(ErrorCode::BadRequest,
                fmt::format("Pose.velocity: a speed of {:.6g} m/s exceeds the server's limit of "
                            "{:.6g} m/s",
                            speed, cfg.maxSpeedMps));
  // Speed over the ground: the client's velocity, else the step since the
  // last pose; the gait follows it, and its phase counts from when it changed.
  const Clock::time_point now = Clock::now();
  float groundSpeed = std::hypot(v.x, v.z);
  if (!pose.velocity() && hasPose_) {
    const double dt = std::chrono::duration<double>(now - lastPoseAt_).count();
    groundSpeed = dt > 0.02 ? float(std::hypot(p.x - position_.x, p.z - position_.z) / dt) : 0.0f;
  }
  const uint8_t gait = uint8_t(gaitForSpeed(groundSpeed));
  if (gait != gait_ || lastPoseAt_ == Clock::time_point{}) gaitSince_ = now;
  gait_ = gait;
  lastPoseAt_ = now;
  position_ = p;
  const auto cell = world_.cellOf(glm::vec3(position_));
  hasPose_ = cell.has_value();
  if (cell) cell_ = *cell;
  scheduler_->setPose(p, v, pose.yaw_deg(), pose.pitch_deg());
  {
    std::lock_guard lock(snapshotMutex_);
    snapshot_.hasPose = hasPose_;
    snapshot_.position = position_;
    snapshot_.yawDeg = pose.yaw_deg();
    snapshot_.pitchDeg = pose.pitch_deg();
    snapshot_.cell = cell_;
    snapshot_.speedMps = groundSpeed;
    snapshot_.gait = gait_;
    snapshot_.gaitSince = gaitSince_;
  }
  pump();
}

void Session::onPvsRequest(const PvsRequest& request) {
  std::optional<glm::ivec3> cell;
  if (request.by_cell()) {
    const glm::ivec3 c = request.cell() ? fromWire(*request.cell()) : glm::ivec3(-1);
    if (world_.grid().contains(c)) cell = c;
  } else if (isFinite(request.point())) {
    const glm::dvec3 rel = (fromWire(*request.point()) - glm::dvec3(world_.grid().origin())) /
                           glm::dvec3(world_.grid().cellSize());
    const glm::dvec3 f = glm::floor(rel);
    // In double, and range-checked before the conversion to int.
    if (glm::all(glm::greaterThanEqual(f, glm::dvec3(0.0))) &&
        glm::all(glm::lessThan(f, glm::dvec3(world_.grid().dims()))))
      cell = glm::ivec3(f);
  }
  const uint32_t requestId = request.request_id();
  if (!cell) {
    PvsReplyT reply;
    reply.request_id = requestId;
    reply.found = false;
    return send(std::make_shared<const std::vector<uint8_t>>(encodeMessage(std::move(reply))));
  }
  const StreamServerConfig& cfg = server_.config();
  if (pvsWaiting_.size() >= cfg.maxPvsRequestsWaiting)
    return fail(ErrorCode::RateLimited,
                fmt::format("more than {} PvsRequests waiting for their replies",
                            cfg.maxPvsRequestsWaiting));
  pvsWaiting_.push_back({requestId, *cell});
  dispatchPvsRequests();
}

void Session::onAvatarModelRequest(const AvatarModelRequest& request) {
  const auto& avatars = server_.config().avatarModels;
  const size_t count = avatars ? avatars->models.size() : 0;
  if (request.model() >= count)
    return fail(ErrorCode::BadRequest,
                fmt::format("AvatarModelRequest.model {}: the server offers {} avatar model{}",
                            request.model(), count, count == 1 ? "" : "s"));
  // Once per model a session (a model is up to 8 MiB: no refetch loops).
  if (modelsSent_[request.model()]++)
    return fail(ErrorCode::RateLimited,
                fmt::format("avatar model {} was already sent to this session", request.model()));
  send(avatars->models[request.model()].frame);
}

void Session::dispatchPvsRequests() {
  while (state_ == State::Active && pvsInFlight_ < server_.config().maxPvsRequestsInFlight &&
         !pvsWaiting_.empty()) {
    const PendingPvs r = pvsWaiting_.front();
    pvsWaiting_.pop_front();
    ++pvsInFlight_;
    world_.pvs(
        r.cell, server_.workers(),
        [self = shared_from_this(), r](FaceListPtr faces) {
          std::shared_ptr<const std::vector<uint8_t>> frame;
          if (faces) {
            PvsReplyT reply;
            reply.request_id = r.requestId;
            reply.cell = std::make_unique<CellIndex>(toWire(r.cell));
            reply.face_ids = *faces;
            reply.found = true;
            frame = std::make_shared<const std::vector<uint8_t>>(encodeMessage(std::move(reply)));
          }
          asio::post(self->strand_, [self, frame, r] {
            --self->pvsInFlight_;
            if (self->state_ != State::Active) return;
            if (!frame)
              return self->fail(ErrorCode::Internal,
                                fmt::format("the PVS of cell ({}, {}, {}) could not be computed",
                                            r.cell.x, r.cell.y, r.cell.z));
            self->send(frame);
            self->dispatchPvsRequests();
          });
        },
        pvsInterest_);
  }
}

void Session::cancelWork() {
  if (scheduler_) scheduler_->cancelAll();
  pvsWaiting_.clear();
  pvsInterest_.reset();
}

void Session::fail(ErrorCode code, const std::string& text) {
  if (state_ == State::Closed || state_ == State::Closing) return;
  server_.peerWarnings().warn("session {}: {} ({}); closing it", id_, text,
                              EnumNameErrorCode(code));
  cancelWork();
  state_ = State::Closing;  // before the send, which may close (see shutdown)
  closingSince_ = Clock::now();
  send(std::make_shared<const std::vector<uint8_t>>(encodeError(code, text)));
}

void Session::close(const char* why) {
  if (state_ == State::Closed) return;
  state_ = State::Closed;
  spdlog::debug("session {}: closed ({}), {} bytes sent", id_, why, bytesSent_);
  boost::system::error_code ignored;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
  socket_.close(ignored);
  housekeepingTimer_.cancel();
  cancelWork();
  outbox_.clear();
  queuedAtomic_ = 0;
  {
    std::lock_guard lock(snapshotMutex_);
    snapshot_.active = false;
  }
  server_.sessionEnded(id_, hasPose_);
}

void Session::send(std::shared_ptr<const std::vector<uint8_t>> frame) {
  if (state_ == State::Closed) return;
  const bool withinLimit = outbox_.push(std::move(frame));
  queuedAtomic_ = outbox_.queuedBytes();
  if (!withinLimit) {
    server_.peerWarnings().warn("session {}: client is not reading ({} bytes queued); closing it",
                                id_, outbox_.queuedBytes());
    close("not reading");
    return;
  }
  writeNext();
}

void Session::writeNext() {
  if (state_ == State::Closed) return;
  Outbox::Frame frame = outbox_.startWrite();
  if (!frame) return;
  writeStarted_ = Clock::now();
  // The handler holds the frame: close() may clear the queue while the
  // write is still in flight.
  asio::async_write(
      socket_, asio::buffer(*frame),
      asio::bind_executor(strand_, [self = shared_from_this(), frame](
                                       const boost::system::error_code& ec, size_t n) {
        if (self->state_ == State::Closed) return self->outbox_.abandonWrite();
        if (ec) {
          self->outbox_.abandonWrite();
          return self->close("write error");
        }
        self->bytesSent_ += n;
        self->server_.countSent(n);
        self->outbox_.finishWrite();
        self->queuedAtomic_ = self->outbox_.queuedBytes();
        if (self->state_ == State::Closing && self->outbox_.empty()) return self->close("closing");
        self->writeNext();
        self->pump();
      }));
}

void Session::housekeeping() {
  if (state_ == State::Closed) return;
  const StreamServerConfig& cfg = server_.config();
  const auto now = Clock::now();
  if (state_ == State::Closing && seconds(now - closingSince_) > 2.0)
    return close("closing timed out");
  if (state_ == State::AwaitHello && seconds(now - started_) > cfg.helloTimeoutS)
    return fail(ErrorCode::Timeout, fmt::format("no Hello within {:.1f} s", cfg.helloTimeoutS));
  if (state_ == State::Active && seconds(now - lastInbound_) > cfg.idleTimeoutS)
    return fail(ErrorCode::Timeout,
                fmt::format("no whole frame received for {:.1f} s", cfg.idleTimeoutS));
  if ((state_ == State::AwaitHello || state_ == State::Active) && midFrame_ &&
      seconds(now - frameStarted_) > cfg.frameTimeoutS)
    return fail(ErrorCode::Timeout,
                fmt::format("a frame begun {:.1f} s ago is still incomplete ({} bytes buffered)",
                            seconds(now - frameStarted_), decoder_.buffered()));
  if (outbox_.writing() && seconds(now - writeStarted_) > cfg.writeStallTimeoutS) {
    server_.peerWarnings().warn("session {}: a write has not finished in {:.1f} s; closing it", id_,
                                cfg.writeStallTimeoutS);
    return close("write stalled");
  }
  if (state_ == State::Active && seconds(now - lastClientStats_) >= statsIntervalS_) {
    lastClientStats_ = now;
    StatsT s;
    s.server_time_s = seconds(now.time_since_epoch());
    s.sessions = uint32_t(server_.sessionCount());
    s.bytes_sent = bytesSent_;
    s.faces_held = scheduler_->heldCount();
    s.cells_ready = scheduler_->cellsReady();
    s.queue_bytes = uint32_t(std::min<size_t>(outbox_.queuedBytes(), UINT32_MAX));
    s.server_cpu_ms_per_s = server_.cpuMsPerSecond();
    send(std::make_shared<const std::vector<uint8_t>>(encodeMessage(std::move(s))));
  }
  pump();  // the bandwidth bucket refills
  housekeepingTimer_.expires_after(std::chrono::milliseconds(100));
  housekeepingTimer_.async_wait(asio::bind_executor(
      strand_, [self = shared_from_this()](const boost::system::error_code& ec) {
        if (!ec) self->housekeeping();
      }));
}

// ---- streaming ------------------------------------------------------------------

void Session::requestFaceSets() {
  const StreamServerConfig& cfg = server_.config();
  const double now = seconds(Clock::now().time_since_epoch());
  for (StreamScheduler::CellRequest& r : scheduler_->takeCellRequests(now)) {
    const uint32_t l = r.cell;
    const CellLevel level = r.level;
    // A dropped prefetch is asked again later (StreamScheduler::onDropped).
    auto dropped = [weak = weak_from_this(), l, level] {
      if (auto self = weak.lock())
        asio::post(self->strand_, [self, l, level] {
          if (self->state_ != State::Active) return;
          self->scheduler_->onDropped(l, level, seconds(Clock::now().time_since_epoch()));
        });
    };
    world_.cellFaceSet(
        world_.grid().cellAt(l), level, cfg.policy, scheduler_->radius(), server_.workers(),
        [self = shared_from_this(), l, level](FaceListPtr faces) {
          asio::post(self->strand_, [self, l, level, faces] {
            if (self->state_ != State::Active || !self->scheduler_->isRequested(l, level)) return;
            if (!faces) {
              const glm::ivec3 c = self->world_.grid().cellAt(l);
              return self->fail(
                  ErrorCode::Internal,
                  fmt::format("the face set of cell ({}, {}, {}) could not be computed", c.x, c.y,
                              c.z));
            }
            if (self->scheduler_->onFaceSet(l, faces, level)) self->pump();
          });
        },
        CellWork{r.priority, r.interest, std::move(dropped)});
  }
}

void Session::maybeCull() {
  // Culling orders the first faces sent; while the workers are behind it
  // would only delay them.
  if (cullingInFlight_ || behind_) return;
  const double now = seconds(Clock::now().time_since_epoch());
  const auto request = scheduler_->takeCullRequest(now);
  if (!request) return;
  cullingInFlight_ = true;
  if (!viewer_) {
    CullingOptions o;
    o.method = CullingMethod::HierarchyUpdating;
    o.collectFaces = true;
    viewer_ = std::make_unique<CullingViewer>(world_.culling(), o);
  }
  // In the work queue with the current cells (one per session at most):
  // streaming waits for it unless the workers are behind.
  auto ended = [weak = weak_from_this()] {
    if (auto self = weak.lock())
      asio::post(self->strand_, [self] { self->cullingInFlight_ = false; });
  };
  world_.work().submit(
      server_.workers().get_executor(), {WorkPriority::Current, now},
      [self = shared_from_this(), r = *request] {
        const FrameResult result = self->viewer_->frame(r.eye, r.yawDeg, r.pitchDeg);
        FaceList visible;
        std::set_intersection(result.faces.begin(), result.faces.end(), r.faceSet->begin(),
                              r.faceSet->end(), std::back_inserter(visible));
        asio::post(self->strand_, [self, visible = std::move(visible), cell = r.cell]() mutable {
          self->cullingInFlight_ = false;
          if (self->state_ != State::Active) return;
          self->scheduler_->onCulled(cell, std::move(visible));
          self->pump();
        });
      },
      ended);
}

void Session::runFirst(std::function<void()> job) {
  // A short job a client waits for (encoding its next batch): rank
  // Immediate, before every computation waiting in the work queue, so a
  // crowd of PVSs does not hold back the faces already known (nor counts
  // as the workers falling behind).
  world_.work().submit(server_.workers().get_executor(), {WorkPriority::Immediate, 0.0},
                       std::move(job));
}

void Session::sendReadyCells() {
  // Every cell that became ready goes in one frame (protocol version 3).
  std::vector<glm::ivec3> cells;
  for (const StreamScheduler::ReadyCell& c : scheduler_->takeReadyCells()) cells.push_back(c.cell);
  if (!cells.empty()) send(std::make_shared<const std::vector<uint8_t>>(encodeCellReady(cells)));
}

bool Session::sendImpostors() {
  const std::vector<uint32_t>& needed = scheduler_->neededCells();
  if (needed.empty()) return false;
  if (needed.front() != impostorCurrent_) {
    impostorCurrent_ = needed.front();
    batchesInCell_ = 0;
  }
  // The current cell's impostors after its first batch (the faces in view
  // go first); the cells ahead only when no geometry is due. Never more
  // view cells than the client keeps; cells merged into one view cell
  // (impostor_database.h) share its impostors, sent once.
  std::vector<uint32_t> views;
  for (size_t k = 0; k < needed.size() && views.size() < wire::kImpostorCellsHeld; ++k) {
    const uint32_t view = world_.impostorViewCell(needed[k]);
    if (std::find(views.begin(), views.end(), view) != views.end()) continue;
    views.push_back(view);
    if (std::find(impostorCells_.begin(), impostorCells_.end(), view) != impostorCells_.end())
      continue;
    const bool due = views.size() == 1 ? batchesInCell_ > 0 || !scheduler_->worthABatch()
                                       : !scheduler_->worthABatch();
    if (!due) return false;
    impostorCells_.push_back(view);
    if (impostorCells_.size() > wire::kImpostorCellsHeld) impostorCells_.pop_front();
    produceInFlight_ = true;
    runFirst([self = shared_from_this(), cell = view] {
      const std::shared_ptr<const CellRecord> record = self->world_.impostorRecord(cell);
      std::vector<std::shared_ptr<const std::vector<uint8_t>>> frames;
      wire::ImpostorMessage m;
      m.cell = self->world_.grid().cellAt(cell);
      if (record) m.cellHi = record->viewHi;
      m.why = record ? record->why : std::string("the impostor bake did not visit this cell");
      if (!record || record->impostors.empty()) {
        frames.push_back(
            std::make_shared<const std::vector<uint8_t>>(wire::encodeImpostorMessage(m)));
      } else {
        m.count = uint32_t(record->impostors.size());
        for (size_t i = 0; i < record->impostors.size(); ++i) {
          const StoredImpostor& s = record->impostors[i];
          m.index = uint32_t(i);
          m.sector = s.sector;
          m.band = s.band;
          m.replacedFaces = s.faces;
          m.data = s.bytes;
          frames.push_back(
              std::make_shared<const std::vector<uint8_t>>(wire::encodeImpostorMessage(m)));
          m.why.clear();  // said with the first
        }
      }
      asio::post(self->strand_, [self, frames = std::move(frames)] {
        self->produceInFlight_ = false;
        if (self->state_ != State::Active) return;
        // One frame a pump, below the outbox's watermark like geometry.
        self->impostorFrames_.insert(self->impostorFrames_.end(), frames.begin(), frames.end());
        self->pump();
      });
    });
    return true;
  }
  return false;
}

void Session::pump() {
  const StreamServerConfig& cfg = server_.config();
  if (state_ != State::Active || cfg.pvsOnly || !wantsGeometry_ || !scheduler_ ||
      !scheduler_->hasPose())
    return;
  // Behind on current cells: no culling, no prefetch, no refinement. With
  // enough prefetch already waiting: no more prefetch or refinement.
  const WorkQueue::Load load = world_.work().load();
  behind_ = load.oldestCurrentS > cfg.behindLagS || load.waitingCurrent > cfg.behindQueuedJobs;
  scheduler_->setBehind(behind_ || load.waitingDroppable > cfg.maxWaitingPrefetch);
  scheduler_->setLagging(load.oldestCurrentS > cfg.behindLagS);
  requestFaceSets();
  maybeCull();
  if (produceInFlight_ || outbox_.queuedBytes() > cfg.geometryWatermarkBytes) return;
  // Nothing goes before the current cell's face set is known, and under the
  // visibility policy before its culling: what the client sees from its pose
  // goes first. (maybeCull starts the culling of a new current cell at once;
  // its result pumps again.)
  if (!scheduler_->readyToStream(cullingInFlight_ && !behind_)) return;
  if (cfg.maxClientKbps > 0.0) {
    const auto now = Clock::now();
    const double rate = cfg.maxClientKbps * 1000.0 / 8.0;  // bytes per second
    tokens_ = std::min(std::max(rate * 0.25, double(cfg.batchBytes)),
                       tokens_ + rate * seconds(now - lastRefill_));
    lastRefill_ = now;
    if (tokens_ <= 0.0) return;  // housekeeping pumps again as the bucket refills
  }
  if (std::vector<uint32_t> evicted = scheduler_->takeEvictions(); !evicted.empty()) {
    EvictT evict;
    evict.face_ids = std::move(evicted);
    send(std::make_shared<const std::vector<uint8_t>>(encodeMessage(std::move(evict))));
  }
  // Pending impostor frames take turns with geometry that is due, so a
  // cell's megabytes of impostors do not hold back the faces of the next.
  if (!impostorFrames_.empty() && (impostorTurn_ || !scheduler_->worthABatch())) {
    impostorTurn_ = false;
    const auto frame = impostorFrames_.front();
    impostorFrames_.pop_front();
    tokens_ -= double(frame->size());
    return send(frame);  // the write's completion pumps again
  }
  if (wantsImpostors_ && impostorFrames_.empty() && sendImpostors()) return;
  std::vector<uint32_t> batch = scheduler_->takeBatch();
  if (batch.empty()) return sendReadyCells();
  ++batchesInCell_;
  impostorTurn_ = true;
  produceInFlight_ = true;
  runFirst([self = shared_from_this(), batch = std::move(batch)] {
    std::vector<FaceTriangles> faces;
    faces.reserve(batch.size());
    for (uint32_t f : batch) faces.push_back(self->world_.face(f));
    const QuantizationGrid grid = QuantizationGrid::forBounds(self->world_.scene().bounds());
    auto frame =
        std::make_shared<const std::vector<uint8_t>>(encodeMessage(encodeGeometry(faces, grid)));
    asio::post(self->strand_, [self, frame] {
      self->produceInFlight_ = false;
      if (self->state_ != State::Active) return;
      self->tokens_ -= double(frame->size());
      self->send(frame);
      self->sendReadyCells();
      self->pump();
    });
  });
}

}  // namespace vistream
