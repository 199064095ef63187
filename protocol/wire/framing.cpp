#include "protocol/wire/framing.h"

#include <fmt/format.h>

namespace vistream::wire {

std::vector<uint8_t> encodeFrame(const flatbuffers::FlatBufferBuilder& builder) {
  const uint32_t size = builder.GetSize();
  std::vector<uint8_t> out(kFrameHeaderBytes + size);
  for (size_t i = 0; i < kFrameHeaderBytes; ++i) out[i] = uint8_t(size >> (8 * i));
  std::copy_n(builder.GetBufferPointer(), size, out.begin() + kFrameHeaderBytes);
  return out;
}

std::vector<uint8_t> encodeHello(uint32_t version, const std::string& token) {
  flatbuffers::FlatBufferBuilder b;
  const auto hello = CreateHelloDirect(b, version, token.c_str());
  b.Finish(CreateEnvelope(b, Payload::Hello, hello.Union()));
  return encodeFrame(b);
}

std::vector<uint8_t> encodeError(ErrorCode code, const std::string& text) {
  flatbuffers::FlatBufferBuilder b;
  const auto err = CreateErrorDirect(b, code, text.c_str());
  b.Finish(CreateEnvelope(b, Payload::Error, err.Union()));
  return encodeFrame(b);
}

std::vector<uint8_t> encodeBye(const std::string& reason) {
  flatbuffers::FlatBufferBuilder b;
  const auto bye = CreateByeDirect(b, reason.c_str());
  b.Finish(CreateEnvelope(b, Payload::Bye, bye.Union()));
  return encodeFrame(b);
}

bool FrameDecoder::feed(std::span<const uint8_t> bytes) {
  if (failed()) return false;
  // Compact before growing so the buffer never holds more than one frame
  // plus one read's worth of bytes.
  if (start_ > 0 && start_ == buffer_.size()) {
    buffer_.clear();
    start_ = 0;
  } else if (start_ > (1u << 16)) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + std::ptrdiff_t(start_));
    start_ = 0;
  }
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
  if (buffered() >= kFrameHeaderBytes) {
    uint32_t size = 0;
    for (size_t i = 0; i < kFrameHeaderBytes; ++i) size |= uint32_t(buffer_[start_ + i]) << (8 * i);
    if (size > max_) {
      error_ = fmt::format("frame of {} bytes exceeds the maximum of {}", size, max_);
      kind_ = FrameError::TooLarge;
      buffer_.clear();
      start_ = 0;
      return false;
    }
  }
  return true;
}

std::optional<std::vector<uint8_t>> FrameDecoder::next() {
  if (failed() || buffered() < kFrameHeaderBytes) return std::nullopt;
  uint32_t size = 0;
  for (size_t i = 0; i < kFrameHeaderBytes; ++i) size |= uint32_t(buffer_[start_ + i]) << (8 * i);
  if (size > max_) {
    error_ = fmt::format("frame of {} bytes exceeds the maximum of {}", size, max_);
    kind_ = FrameError::TooLarge;
    return std::nullopt;
  }
  if (buffered() < kFrameHeaderBytes + size) return std::nullopt;
  const uint8_t* data = buffer_.data() + start_ + kFrameHeaderBytes;
  // Verified in its own allocation: FlatBuffers aligns fields relative to
  // the buffer's start, so it must start aligned (the stream offset need not be).
  std::vector<uint8_t> frame(data, data + size);
  flatbuffers::Verifier verifier(frame.data(), frame.size());
  if (size == 0 || !VerifyEnvelopeBuffer(verifier)) {
    error_ = fmt::format("frame of {} bytes failed FlatBuffers verification", size);
    kind_ = FrameError::Malformed;
    return std::nullopt;
  }
  // The Verifier accepts a union whose type is set but whose table is
  // absent; every reader would then dereference null. Not a valid message.
  const Envelope* envelope = GetEnvelope(frame.data());
  if (envelope->payload_type() != Payload::NONE && envelope->payload() == nullptr) {
    error_ = fmt::format("frame of {} bytes names a {} payload but carries none", size,
                         EnumNamePayload(envelope->payload_type()));
    kind_ = FrameError::Malformed;
    return std::nullopt;
  }
  start_ += kFrameHeaderBytes + size;
  return frame;
}

}  // namespace vistream::wire
