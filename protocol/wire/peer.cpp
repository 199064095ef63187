#include "protocol/wire/peer.h"

#include <fmt/format.h>

#include <boost/asio/dispatch.hpp>
#include <boost/asio/write.hpp>
#include <cmath>

namespace vistream::wire {

namespace asio = boost::asio;

namespace {
[[noreturn]] void badWelcome(const std::string& what) {
  throw InputError(InputErrorCode::BadFrame, "Welcome." + what);
}

glm::vec3 finiteVec3(const Vec3f* v, const char* field) {
  if (!v) badWelcome(fmt::format("{} is missing", field));
  if (!isFinite(v)) badWelcome(fmt::format("{} is not finite", field));
  return fromWire(*v);
}
}  // namespace

WelcomeGrid validateWelcome(const Welcome& w, uint32_t maxFaceCount) {
  WelcomeGrid g;
  if (!w.grid()) badWelcome("grid is missing");
  g.gridOrigin = finiteVec3(w.grid()->origin(), "grid.origin");
  g.cellSize = finiteVec3(w.grid()->cell_size(), "grid.cell_size");
  if (!(g.cellSize.x > 0.0f && g.cellSize.y > 0.0f && g.cellSize.z > 0.0f))
    badWelcome(fmt::format("grid.cell_size ({}, {}, {}) is not positive in every axis",
                           g.cellSize.x, g.cellSize.y, g.cellSize.z));
  if (!w.grid()->dims()) badWelcome("grid.dims is missing");
  g.dims = fromWire(*w.grid()->dims());
  if (glm::any(glm::lessThan(g.dims, glm::ivec3(0))))
    badWelcome(fmt::format("grid.dims ({}, {}, {}) is negative", g.dims.x, g.dims.y, g.dims.z));
  if (!w.local_origin()) badWelcome("local_origin is missing");
  if (!isFinite(w.local_origin())) badWelcome("local_origin is not finite");
  g.localOrigin = fromWire(*w.local_origin());
  g.radius = w.near_field_radius_m();
  if (!(std::isfinite(g.radius) && g.radius >= 0.0f))
    badWelcome(fmt::format("near_field_radius_m {} is not finite and >= 0", g.radius));
  g.faceCount = w.face_count();
  if (g.faceCount > maxFaceCount)
    badWelcome(
        fmt::format("face_count {} is more than the limit of {}", g.faceCount, maxFaceCount));
  if (!w.quant_origin()) badWelcome("quant_origin is missing");
  if (!isFinite(w.quant_origin())) badWelcome("quant_origin is not finite");
  g.quantization.origin = fromWire(*w.quant_origin());
  g.quantization.step = w.quant_step();
  // A step over a kilometre is no scene's; it bounds every decoded position.
  if (!(g.quantization.step > 0.0 && g.quantization.step <= 1e3))
    badWelcome(fmt::format("quant_step {} is not in (0, 1000] metres", g.quantization.step));
  return g;
}

std::shared_ptr<Peer> Peer::create(Strand strand, const PeerOptions& options) {
  return std::make_shared<Peer>(std::move(strand), options);
}

Peer::Peer(Strand strand, const PeerOptions& options)
    : strand_(std::move(strand)),
      socket_(strand_),
      decoder_(options.maxFrameBytes),
      outbox_(options.outboxLimitBytes) {}

void Peer::start(std::weak_ptr<PeerHandler> handler) {
  handler_ = std::move(handler);
  read();
}

void Peer::send(std::vector<uint8_t> frame) {
  if (!open_) return;  // nothing would carry it, and a post might never run
  asio::dispatch(strand_, [self = shared_from_this(),
                           frame = std::make_shared<const std::vector<uint8_t>>(
                               std::move(frame))]() mutable { self->queue(std::move(frame)); });
}

void Peer::close() {
  if (!open_.exchange(false)) return;
  boost::system::error_code ignored;
  socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
  socket_.close(ignored);
  outbox_.clear();
}

void Peer::read() {
  socket_.async_read_some(
      asio::buffer(buffer_),
      [self = shared_from_this()](const boost::system::error_code& ec, size_t n) {
        if (!self->open_) return;
        if (ec) return self->end(PeerEnd::ConnectionLost, ec.message());
        self->bytesReceived_ += n;
        if (!self->decoder_.feed(std::span<const uint8_t>(self->buffer_.data(), n)))
          return self->end(PeerEnd::BadFrame, self->decoder_.error());
        const std::shared_ptr<PeerHandler> handler = self->handler_.lock();
        if (!handler) return self->close();  // nobody listens any more
        while (self->open_) {
          const auto frame = self->decoder_.next();
          if (!frame) break;
          self->frameBytes_ = frame->size() + kFrameHeaderBytes;
          handler->onFrame(*envelopeOf(*frame));
        }
        if (!self->open_) return;
        if (self->decoder_.failed()) return self->end(PeerEnd::BadFrame, self->decoder_.error());
        self->read();
      });
}

void Peer::queue(Outbox::Frame frame) {
  if (!open_) return;
  if (!outbox_.push(std::move(frame)))
    return end(PeerEnd::OutboxFull,
               fmt::format("{} bytes queued for sending, more than the limit of {}",
                           outbox_.queuedBytes(), outbox_.limitBytes()));
  writeNext();
}

void Peer::writeNext() {
  if (!open_) return;
  Outbox::Frame frame = outbox_.startWrite();
  if (!frame) return;
  // The handler holds the frame: close() may clear the outbox mid-write.
  asio::async_write(
      socket_, asio::buffer(*frame),
      [self = shared_from_this(), frame](const boost::system::error_code& ec, size_t n) {
        if (!self->open_) return self->outbox_.abandonWrite();
        if (ec) {
          self->outbox_.abandonWrite();
          return self->end(PeerEnd::WriteFailed, ec.message());
        }
        self->bytesSent_ += n;
        self->outbox_.finishWrite();
        self->writeNext();
      });
}

void Peer::end(PeerEnd why, const std::string& text) {
  if (!open_) return;
  close();
  if (const std::shared_ptr<PeerHandler> handler = handler_.lock()) handler->onPeerEnd(why, text);
}

}  // namespace vistream::wire
