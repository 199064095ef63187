// Frames on the wire: a 4-byte little-endian payload length, then a
// FlatBuffer with an Envelope root (protocol/schema/vistream.fbs).
//
// FrameDecoder is the only way inbound bytes become messages: it enforces the
// maximum frame size before buffering, and runs the FlatBuffers Verifier on
// every frame before anything reads it. It is safe on arbitrary bytes: a
// malformed stream yields an error, never a crash, and memory stays bounded
// by the maximum frame size. Not thread-safe: one decoder per connection.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/core/error.h"
#include "vistream_generated.h"

namespace vistream::wire {

// 2: compact Geometry, the quantization grid in Welcome; 3: CellReady for
// several cells at once, the Stats interval in Capabilities.
inline constexpr uint32_t kProtocolVersion = 3;
inline constexpr uint32_t kDefaultMaxFrameBytes = 16u << 20;  // 16 MiB
inline constexpr size_t kFrameHeaderBytes = 4;

// Prefixes a finished builder's buffer with its length.
std::vector<uint8_t> encodeFrame(const flatbuffers::FlatBufferBuilder& builder);

// Convenience encoders for the small control messages.
std::vector<uint8_t> encodeHello(uint32_t version, const std::string& token);
std::vector<uint8_t> encodeError(ErrorCode code, const std::string& text);
std::vector<uint8_t> encodeBye(const std::string& reason);

// Why a stream was refused: a frame longer than the maximum (known from its
// length prefix alone) or bytes that are not a valid frame.
enum class FrameError : uint8_t { None, TooLarge, Malformed };

class FrameDecoder {
 public:
  explicit FrameDecoder(uint32_t maxFrameBytes = kDefaultMaxFrameBytes) : max_(maxFrameBytes) {}

  // Appends received bytes. Returns false (and sets error()) once the stream
  // is known to be bad; after that the decoder accepts nothing more.
  bool feed(std::span<const uint8_t> bytes);

  // The next complete, verified frame's bytes (without the length prefix),
  // or nothing if no complete frame is buffered yet or the stream is bad.
  // A verified frame's envelope always carries the payload its type names.
  std::optional<std::vector<uint8_t>> next();

  bool failed() const { return !error_.empty(); }
  const std::string& error() const { return error_; }
  // The same kind for the same bytes, however they were split into reads.
  FrameError errorKind() const { return kind_; }
  // The same as an InputError code: TooLarge or BadFrame (Invalid while none).
  InputErrorCode errorCode() const {
    return kind_ == FrameError::TooLarge    ? InputErrorCode::TooLarge
           : kind_ == FrameError::Malformed ? InputErrorCode::BadFrame
                                            : InputErrorCode::Invalid;
  }
  size_t buffered() const { return buffer_.size() - start_; }

 private:
  uint32_t max_;
  std::vector<uint8_t> buffer_;
  size_t start_ = 0;
  std::string error_;
  FrameError kind_ = FrameError::None;
};

// The verified envelope inside a frame returned by FrameDecoder::next().
inline const Envelope* envelopeOf(const std::vector<uint8_t>& frame) {
  return GetEnvelope(frame.data());
}

}  // namespace vistream::wire
