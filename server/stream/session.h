// One client connection of the streaming server (see stream_server.h).
//
// The conversation: the client sends Hello; the server answers Welcome (or
// Error and closes). Then the client sends Pose whenever it moves; the server
// streams Geometry for the faces of the client's current cell first (those
// visible from the pose before the rest), then the cells ahead of it, sends
// CellReady when the client holds a cell's whole face set, ImpostorData (when
// the Hello asked for impostors and the server has them) for the current
// cell after its first batch and for the cells ahead when nothing else is due, Evict when the
// client's memory budget would be exceeded, Avatar updates and Stats. A
// PvsRequest is answered with a PvsReply at any time after Welcome. Bye
// from either side ends the session.
//
// Every handler runs on the session's strand; work for the worker pool
// captures a shared_ptr to the session and posts its result back.
//
// The session is the transport: it reads and checks frames, holds the
// conversation's state and moves bytes. It is built from the protocol peer
// core's parts (protocol/wire/peer.h): FrameDecoder, dispatchPayload, the
// Outbox's queue rules and wireErrorCode; its read loop is a Peer's plus an
// inbound rate limit and per-frame deadlines, which is why it is not a Peer. What the client gets
// next is decided by its StreamScheduler (stream_scheduler.h); the session runs the visibility work
// the scheduler asks for on the worker pool and sends what it emits.
//
// What a client can make the server do is bounded: every loop driven by a
// client's values has a fixed number of steps (the scheduler samples at most
// kMaxPrefetchSteps points along the velocity, which must be below
// --max-speed), implausible poses are refused, at most maxCellRequests cell
// face sets and maxPvsRequestsInFlight PvsRequests are outstanding on the
// shared worker pool (the rest wait here, bounded, or are refused), and a
// session that moves on or ends cancels what it no longer needs.
#pragma once

#include <array>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "protocol/wire/peer.h"
#include "server/stream/stream_scheduler.h"
#include "server/stream/stream_world.h"

namespace vistream {

class StreamServer;

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(StreamServer& server, boost::asio::ip::tcp::socket socket, uint32_t id);
  ~Session();

  void start();
  // Sends an Error and closes without reading (too many clients).
  void reject(wire::ErrorCode code, const std::string& text);
  // Says Bye and closes. Thread-safe.
  void shutdown(const std::string& reason);
  // Queues an Avatar frame if the session is active. Thread-safe.
  void deliverAvatars(std::shared_ptr<const std::vector<uint8_t>> frame);

  struct Snapshot {
    uint32_t id = 0;
    bool active = false, hasPose = false, wantsAvatars = false;
    float speedMps = 0.0f;                              // over the ground
    uint8_t gait = 0;                                   // Gait (common/avatar/avatar_model.h)
    std::chrono::steady_clock::time_point gaitSince{};  // when the user took up this gait
    glm::dvec3 position{0.0};
    float yawDeg = 0.0f, pitchDeg = 0.0f, radius = 0.0f;
    glm::ivec3 cell{0};
  };
  Snapshot snapshot() const;  // thread-safe
  uint32_t id() const { return id_; }
  size_t queuedBytes() const { return queuedAtomic_; }

 private:
  using Clock = std::chrono::steady_clock;
  enum class State { AwaitHello, Active, Closing, Closed };

  void read();
  void onFrame(const wire::Envelope& envelope);
  void onHello(const wire::Hello& hello);
  void onPose(const wire::Pose& pose);
  void onPvsRequest(const wire::PvsRequest& request);
  void onAvatarModelRequest(const wire::AvatarModelRequest& request);
  void dispatchPvsRequests();
  void onBytes(std::span<const uint8_t> bytes);
  // Drops every interest in visibility work: queued computations nobody
  // else waits for are not run.
  void cancelWork();
  void fail(wire::ErrorCode code, const std::string& text);
  void close(const char* why);
  void send(std::shared_ptr<const std::vector<uint8_t>> frame);
  void writeNext();
  void housekeeping();

  // Streaming: the scheduler decides, these run its requests and send.
  void pump();
  void requestFaceSets();
  void maybeCull();
  void sendReadyCells();
  // Sends the impostors of the next needed cell the client does not hold,
  // if one is due now; true if it started.
  bool sendImpostors();
  // Runs `job` on the workers before any visibility computation waiting.
  void runFirst(std::function<void()> job);

  StreamServer& server_;
  StreamWorld& world_;
  boost::asio::strand<boost::asio::io_context::executor_type> strand_;
  boost::asio::ip::tcp::socket socket_;
  boost::asio::steady_timer housekeepingTimer_;
  const uint32_t id_;
  State state_ = State::AwaitHello;
  wire::FrameDecoder decoder_;
  std::array<uint8_t, 16384> readBuffer_{};
  bool midFrame_ = false;           // part of a frame is buffered
  Clock::time_point frameStarted_;  // when its first byte arrived

  wire::Outbox outbox_;  // the send queue (protocol/wire/peer.h): one write in flight
  std::atomic<size_t> queuedAtomic_{0};  // outbox_.queuedBytes(), for other threads
  Clock::time_point writeStarted_, lastInbound_, started_, closingSince_, lastClientStats_,
      windowStart_;
  unsigned framesInWindow_ = 0;
  uint64_t bytesSent_ = 0;

  // Client capabilities.
  float radius_ = 0.0f;
  double statsIntervalS_ = 0.0;  // seconds between Stats frames (the client's, or the server's)
  uint64_t budget_ = 0;
  bool wantsGeometry_ = true, wantsAvatars_ = true;
  // Impostors (the client asked, the server has them): the view cells (their
  // leaders, StreamWorld::impostorViewCell) whose
  // impostors the client holds, oldest first, as the client keeps them
  // (at most wire::kImpostorCellsHeld); batches sent since the current cell
  // changed (its impostors go after its first batch).
  bool wantsImpostors_ = false;
  std::deque<uint32_t> impostorCells_;
  std::deque<std::shared_ptr<const std::vector<uint8_t>>> impostorFrames_;  // made, not yet queued
  uint32_t impostorCurrent_ = UINT32_MAX;
  unsigned batchesInCell_ = 0;
  bool impostorTurn_ = false;  // the next pending impostor frame goes before the next batch

  // Pose (as last received; the scheduler has its own copy).
  bool hasPose_ = false;
  Clock::time_point lastPoseAt_{};
  uint8_t gait_ = 0;
  Clock::time_point gaitSince_{};
  std::vector<uint8_t> modelsSent_;  // per avatar model: AvatarModelData frames sent
  glm::dvec3 position_{0.0};
  glm::ivec3 cell_{0};
  mutable std::mutex snapshotMutex_;  // guards snapshot_
  Snapshot snapshot_;

  // What the client gets next (created at Hello), and the work in flight for it.
  std::unique_ptr<StreamScheduler> scheduler_;
  bool cullingInFlight_ = false, produceInFlight_ = false;
  bool behind_ = false;  // the workers are behind (WorkQueue::behind): no prefetch, no culling
  std::unique_ptr<CullingViewer> viewer_;
  struct PendingPvs {
    uint32_t requestId;
    glm::ivec3 cell;
  };
  std::deque<PendingPvs> pvsWaiting_;
  unsigned pvsInFlight_ = 0;
  Interest pvsInterest_ = makeInterest();
  double tokens_ = 0.0;
  Clock::time_point lastRefill_;
};

}  // namespace vistream
