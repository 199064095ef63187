// The protocol peer core: what every end of a vistream connection shares.
//
// - validateWelcome: the checks a client applies to the server's Welcome
//   beyond the FlatBuffers Verifier (every value it computes with is present
//   and finite, the cell size positive), so no peer divides by a zero cell.
// - dispatchPayload: typed dispatch of a verified Envelope, one handler
//   overload per payload type and one for the types a peer does not handle.
// - Outbox: the send queue's rules (a deque of shared frames, exactly one
//   write in flight, a byte count checked against a hard limit on every push).
// - Peer: an Asio connection built from the above and FrameDecoder
//   (framing.h): the read loop (async_read_some into a fixed buffer, bytes
//   into the decoder, one handler call per verified frame) and the outbox.
//   StreamClient (client/net) and the load tester's clients
//   (client/loadtest) are Peers. The server's Session (server/stream) keeps
//   its own transport, because its read loop also enforces rate limits and
//   per-frame deadlines, but it is built from the same decoder, dispatch and
//   Outbox.
//
// Errors are InputErrors (common/core/error.h) with code BadFrame naming the
// message and field; a peer sends them on as wire::wireErrorCode(code).
#pragma once

#include <array>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/strand.hpp>
#include <cstdint>
#include <deque>
#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "protocol/geometry/geometry_codec.h"
#include "protocol/wire/messages.h"

namespace vistream::wire {

// ---- Welcome -------------------------------------------------------------------

// What a client computes with from a Welcome, all checked.
struct WelcomeGrid {
  glm::dvec3 localOrigin{0.0};    // file coordinates of the local frame's origin
  glm::vec3 gridOrigin{0.0f};     // local frame, metres
  glm::vec3 cellSize{1.0f};       // metres, every axis finite and positive
  glm::ivec3 dims{1};             // cells per axis, each >= 0
  float radius = 0.0f;            // near-field radius, finite and >= 0 (metres)
  uint32_t faceCount = 0;         // at most the maximum given to validateWelcome
  QuantizationGrid quantization;  // every Geometry's grid: origin finite, step in (0, 1 km]

  // The view cell holding `local` (local frame), clamped into the grid.
  glm::ivec3 cellOf(const glm::vec3& local) const {
    return glm::clamp(glm::ivec3(glm::floor((local - gridOrigin) / cellSize)), glm::ivec3(0),
                      glm::max(dims - 1, glm::ivec3(0)));
  }
};

// A client keeps one bit per face of the scene: more faces than this in a
// Welcome is refused rather than allocated.
inline constexpr uint32_t kMaxWelcomeFaceCount = 64u << 20;

// Checks a verified Welcome; throws InputError (code BadFrame) whose message
// names the first bad field ("Welcome.grid.cell_size ...").
WelcomeGrid validateWelcome(const Welcome& welcome, uint32_t maxFaceCount = kMaxWelcomeFaceCount);

// ---- typed dispatch -----------------------------------------------------------

// Builds one handler from lambdas: dispatchPayload(e, Overloaded{...}).
template <class... F>
struct Overloaded : F... {
  using F::operator()...;
};
template <class... F>
Overloaded(F...) -> Overloaded<F...>;

namespace detail {
template <class T, class Handler>
void dispatchAs(const Envelope& envelope, const T* payload, Handler& handler) {
  if constexpr (std::is_invocable_v<Handler&, const T&>)
    handler(*payload);
  else
    handler(envelope.payload_type());
}
}  // namespace detail

// Calls handler(const T&) with the envelope's payload of type T when the
// handler takes one, otherwise handler(Payload) with the payload's type
// (also for NONE and types newer than this build). The envelope must come
// from FrameDecoder::next(), which guarantees the payload its type names.
template <class Handler>
void dispatchPayload(const Envelope& envelope, Handler&& handler) {
  switch (envelope.payload_type()) {
    case Payload::Hello:
      return detail::dispatchAs(envelope, envelope.payload_as_Hello(), handler);
    case Payload::Welcome:
      return detail::dispatchAs(envelope, envelope.payload_as_Welcome(), handler);
    case Payload::Error:
      return detail::dispatchAs(envelope, envelope.payload_as_Error(), handler);
    case Payload::Bye:
      return detail::dispatchAs(envelope, envelope.payload_as_Bye(), handler);
    case Payload::Pose:
      return detail::dispatchAs(envelope, envelope.payload_as_Pose(), handler);
    case Payload::Geometry:
      return detail::dispatchAs(envelope, envelope.payload_as_Geometry(), handler);
    case Payload::Evict:
      return detail::dispatchAs(envelope, envelope.payload_as_Evict(), handler);
    case Payload::CellReady:
      return detail::dispatchAs(envelope, envelope.payload_as_CellReady(), handler);
    case Payload::Avatar:
      return detail::dispatchAs(envelope, envelope.payload_as_Avatar(), handler);
    case Payload::PvsRequest:
      return detail::dispatchAs(envelope, envelope.payload_as_PvsRequest(), handler);
    case Payload::PvsReply:
      return detail::dispatchAs(envelope, envelope.payload_as_PvsReply(), handler);
    case Payload::Stats:
      return detail::dispatchAs(envelope, envelope.payload_as_Stats(), handler);
    case Payload::AvatarModelRequest:
      return detail::dispatchAs(envelope, envelope.payload_as_AvatarModelRequest(), handler);
    case Payload::AvatarModelData:
      return detail::dispatchAs(envelope, envelope.payload_as_AvatarModelData(), handler);
    case Payload::ImpostorData:
      return detail::dispatchAs(envelope, envelope.payload_as_ImpostorData(), handler);
    default:
      return handler(envelope.payload_type());
  }
}

// ---- Outbox --------------------------------------------------------------------

// The send queue of one connection: frames leave in the order pushed, one
// write at a time, and the bytes queued (including the frame being written)
// are checked against a hard limit on every push. Not thread-safe: used on
// its connection's strand only.
class Outbox {
 public:
  using Frame = std::shared_ptr<const std::vector<uint8_t>>;

  explicit Outbox(size_t limitBytes) : limit_(limitBytes) {}

  // Queues a frame. False when the queue now holds more than the limit: the
  // peer is not reading, and the caller closes the connection.
  bool push(Frame frame) {
    queued_ += frame->size();
    frames_.push_back(std::move(frame));
    return queued_ <= limit_;
  }
  // The frame to write next, marked in flight; null while a write is in
  // flight or nothing is queued. The caller's write handler keeps the frame.
  Frame startWrite() {
    if (writing_ || frames_.empty()) return nullptr;
    writing_ = true;
    return frames_.front();
  }
  // The write in flight completed: its frame, always the front of the
  // queue (clear() keeps it), leaves the queue.
  void finishWrite() {
    if (!writing_) return;
    writing_ = false;
    queued_ -= frames_.front()->size();
    frames_.pop_front();
  }
  // The write in flight failed or was abandoned (the connection is
  // closing): its frame leaves the queue unsent.
  void abandonWrite() { finishWrite(); }
  // Drops every frame not yet being written. The one in flight stays at the
  // front (and in the byte count) until its write completes, so a frame
  // pushed after the clear is the next to go, never mistaken for it.
  void clear() {
    if (writing_) {
      frames_.erase(frames_.begin() + 1, frames_.end());
      queued_ = frames_.front()->size();
    } else {
      frames_.clear();
      queued_ = 0;
    }
  }

  bool writing() const { return writing_; }
  bool empty() const { return frames_.empty(); }
  size_t frames() const { return frames_.size(); }
  size_t queuedBytes() const { return queued_; }
  size_t limitBytes() const { return limit_; }

 private:
  size_t limit_;
  std::deque<Frame> frames_;
  size_t queued_ = 0;
  bool writing_ = false;
};

// ---- Peer ----------------------------------------------------------------------

// Why a Peer ended on its own (not by close()).
enum class PeerEnd : uint8_t {
  ConnectionLost,  // the read failed: the other end closed or reset the connection
  BadFrame,        // the bytes were not a valid frame (text: the decoder's error)
  WriteFailed,     // a write failed
  OutboxFull,      // more than the outbox limit queued: the other end is not reading
};

// What a Peer reports to. Calls run on the peer's strand, one at a time.
class PeerHandler {
 public:
  virtual ~PeerHandler() = default;
  // One verified frame. The handler may call Peer::send and Peer::close;
  // after close() no further frame is delivered.
  virtual void onFrame(const Envelope& envelope) = 0;
  // The peer ended on its own (the connection is already closed); called at
  // most once, and never after close().
  virtual void onPeerEnd(PeerEnd why, const std::string& text) = 0;
};

struct PeerOptions {
  uint32_t maxFrameBytes = kDefaultMaxFrameBytes;  // larger inbound frames end the peer
  size_t outboxLimitBytes = 16u << 20;             // bytes queued for sending before OutboxFull
};

// One connection: the socket, its read loop and its outbox, on a strand.
// Lifetime: handlers of pending operations hold the Peer (shared_from_this);
// the Peer holds its handler weakly, so the owner can hold the Peer without
// a cycle, and an owner that has gone receives nothing.
// Thread safety: send() and bytes*() from any thread; start() and close() on
// the strand (or from any thread while no thread runs the io_context).
class Peer : public std::enable_shared_from_this<Peer> {
 public:
  using Strand = boost::asio::strand<boost::asio::io_context::executor_type>;

  static std::shared_ptr<Peer> create(Strand strand, const PeerOptions& options = {});

  // The socket, to connect (its handlers run on the strand) before start().
  boost::asio::ip::tcp::socket& socket() { return socket_; }
  const Strand& strand() const { return strand_; }

  // Begins the read loop; frames go to `handler`.
  void start(std::weak_ptr<PeerHandler> handler);
  // Queues a frame for sending; dropped once the peer is closed.
  void send(std::vector<uint8_t> frame);
  // Closes the connection: nothing more is read, sent or reported.
  void close();

  bool open() const { return open_; }
  uint64_t bytesReceived() const { return bytesReceived_; }
  uint64_t bytesSent() const { return bytesSent_; }
  // The size on the wire (length prefix included) of the frame being
  // delivered: valid inside PeerHandler::onFrame, on the strand.
  size_t frameBytes() const { return frameBytes_; }

  Peer(Strand strand, const PeerOptions& options);  // use create()

 private:
  void read();
  void queue(Outbox::Frame frame);
  void writeNext();
  void end(PeerEnd why, const std::string& text);

  Strand strand_;
  boost::asio::ip::tcp::socket socket_;
  FrameDecoder decoder_;
  std::array<uint8_t, 1 << 16> buffer_{};
  Outbox outbox_;
  std::weak_ptr<PeerHandler> handler_;
  std::atomic<bool> open_{true};
  std::atomic<uint64_t> bytesReceived_{0}, bytesSent_{0};
  size_t frameBytes_ = 0;
};

}  // namespace vistream::wire
