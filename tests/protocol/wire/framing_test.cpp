#include "protocol/wire/framing.h"

#include <gtest/gtest.h>

namespace vistream::wire {
namespace {

std::vector<uint8_t> concat(std::initializer_list<std::vector<uint8_t>> parts) {
  std::vector<uint8_t> out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

TEST(FrameDecoder, ReturnsTheHelloThatWasEncoded) {
  FrameDecoder decoder;
  ASSERT_TRUE(decoder.feed(encodeHello(kProtocolVersion, "secret")));
  const auto frame = decoder.next();
  ASSERT_TRUE(frame.has_value());
  const Envelope* env = envelopeOf(*frame);
  ASSERT_EQ(env->payload_type(), Payload::Hello);
  EXPECT_EQ(env->payload_as_Hello()->protocol_version(), kProtocolVersion);
  EXPECT_EQ(env->payload_as_Hello()->auth_token()->str(), "secret");
  EXPECT_FALSE(decoder.next().has_value());
}

TEST(FrameDecoder, ReassemblesFramesDeliveredOneByteAtATime) {
  const auto bytes =
      concat({encodeHello(1, "a"), encodeBye("done"), encodeError(ErrorCode::BadToken, "no")});
  FrameDecoder decoder;
  std::vector<Payload> seen;
  for (uint8_t b : bytes) {
    ASSERT_TRUE(decoder.feed(std::span<const uint8_t>(&b, 1)));
    while (auto f = decoder.next()) seen.push_back(envelopeOf(*f)->payload_type());
  }
  EXPECT_EQ(seen, (std::vector<Payload>{Payload::Hello, Payload::Bye, Payload::Error}));
  EXPECT_EQ(decoder.buffered(), 0u);
}

TEST(FrameDecoder, RejectsAFrameLargerThanTheMaximumBeforeBufferingIt) {
  FrameDecoder decoder(1024);
  const std::vector<uint8_t> header = {0x01, 0x00, 0x10, 0x00};  // 1 MiB + 1 claimed
  EXPECT_FALSE(decoder.feed(header));
  EXPECT_TRUE(decoder.failed());
  EXPECT_NE(decoder.error().find("exceeds the maximum"), std::string::npos);
  EXPECT_EQ(decoder.buffered(), 0u);
}

TEST(FrameDecoder, RejectsGarbageThatFailsVerification) {
  FrameDecoder decoder;
  std::vector<uint8_t> bytes = {16, 0, 0, 0};
  for (int i = 0; i < 16; ++i) bytes.push_back(uint8_t(0xA5 + i));
  ASSERT_TRUE(decoder.feed(bytes));
  EXPECT_FALSE(decoder.next().has_value());
  EXPECT_TRUE(decoder.failed());
  EXPECT_NE(decoder.error().find("verification"), std::string::npos);
}

TEST(FrameDecoder, WaitsForTheRestOfATruncatedFrame) {
  const auto frame = encodeBye("later");
  FrameDecoder decoder;
  ASSERT_TRUE(decoder.feed(std::span(frame).first(frame.size() - 1)));
  EXPECT_FALSE(decoder.next().has_value());
  EXPECT_FALSE(decoder.failed());
  ASSERT_TRUE(decoder.feed(std::span(frame).last(1)));
  EXPECT_TRUE(decoder.next().has_value());
}

TEST(FrameDecoder, RejectsAnEmptyFrame) {
  FrameDecoder decoder;
  ASSERT_TRUE(decoder.feed(std::vector<uint8_t>{0, 0, 0, 0}));
  EXPECT_FALSE(decoder.next().has_value());
  EXPECT_TRUE(decoder.failed());
}

// The FlatBuffers Verifier accepts a union whose type is set but whose table
// is missing; readers would dereference null (found in review: one such frame
// crashed the server before authentication).
TEST(FrameDecoder, RejectsAFrameThatNamesAPayloadButCarriesNone) {
  for (Payload type : {Payload::Hello, Payload::Welcome, Payload::Geometry, Payload::Error}) {
    flatbuffers::FlatBufferBuilder b;
    EnvelopeBuilder e(b);
    e.add_payload_type(type);
    b.Finish(e.Finish());
    FrameDecoder decoder;
    ASSERT_TRUE(decoder.feed(encodeFrame(b)));
    EXPECT_FALSE(decoder.next().has_value()) << EnumNamePayload(type);
    EXPECT_TRUE(decoder.failed());
    EXPECT_NE(decoder.error().find("carries none"), std::string::npos) << decoder.error();
  }
}

}  // namespace
}  // namespace vistream::wire
