// The one mapping from InputError codes to the wire's ErrorCode, and the
// codes the frame decoder gives its failures.
#include "protocol/wire/messages.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace vistream::wire {
namespace {

TEST(InputError, CarriesInvalidUnlessGivenACode) {
  EXPECT_EQ(InputError("bad value").code(), InputErrorCode::Invalid);
  EXPECT_EQ(InputError(InputErrorCode::BadFile, "x.obj: cannot open it").code(),
            InputErrorCode::BadFile);
  const InputError thrown = [] {
    try {
      throwInputError(InputErrorCode::TooLarge, "{} triangles", 9);
    } catch (const InputError& e) {
      return e;
    }
  }();
  EXPECT_EQ(thrown.code(), InputErrorCode::TooLarge);
  EXPECT_STREQ(thrown.what(), "9 triangles");
  EXPECT_STREQ(inputErrorCodeName(InputErrorCode::Unreachable), "Unreachable");
  EXPECT_STREQ(inputErrorCodeName(InputErrorCode::Invalid), "Invalid");
}

TEST(WireErrorCode, SendsFrameFailuresWithTheCodesTheProtocolNamesForThem) {
  EXPECT_EQ(wireErrorCode(InputErrorCode::TooLarge), ErrorCode::FrameTooLarge);
  EXPECT_EQ(wireErrorCode(InputErrorCode::BadFrame), ErrorCode::MalformedFrame);
  EXPECT_EQ(wireErrorCode(InputErrorCode::LimitExceeded), ErrorCode::RateLimited);
  EXPECT_EQ(wireErrorCode(InputErrorCode::Unsupported), ErrorCode::NotSupported);
  EXPECT_EQ(wireErrorCode(InputErrorCode::Invalid), ErrorCode::BadRequest);
  EXPECT_EQ(wireErrorCode(InputErrorCode::BadArgument), ErrorCode::BadRequest);
}

TEST(WireErrorCode, BlamesTheReceiverForItsOwnFilesAndNeighbours) {
  // A file the server cannot read or a host it cannot reach is not the
  // client's fault: Internal, not BadRequest.
  EXPECT_EQ(wireErrorCode(InputErrorCode::BadFile), ErrorCode::Internal);
  EXPECT_EQ(wireErrorCode(InputErrorCode::Unreachable), ErrorCode::Internal);
}

TEST(FrameDecoder, GivesAnOversizedFrameTheCodeTooLargeAndGarbageBadFrame) {
  FrameDecoder tooLarge(1024);
  EXPECT_EQ(tooLarge.errorCode(), InputErrorCode::Invalid);  // no failure yet
  EXPECT_FALSE(tooLarge.feed(std::vector<uint8_t>{0x01, 0x00, 0x10, 0x00}));
  EXPECT_EQ(tooLarge.errorCode(), InputErrorCode::TooLarge);
  EXPECT_EQ(wireErrorCode(tooLarge.errorCode()), ErrorCode::FrameTooLarge);

  FrameDecoder garbage;
  std::vector<uint8_t> bytes = {16, 0, 0, 0};
  for (int i = 0; i < 16; ++i) bytes.push_back(uint8_t(0xA5 + i));
  ASSERT_TRUE(garbage.feed(bytes));
  EXPECT_FALSE(garbage.next().has_value());
  EXPECT_EQ(garbage.errorCode(), InputErrorCode::BadFrame);
  EXPECT_EQ(wireErrorCode(garbage.errorCode()), ErrorCode::MalformedFrame);
}

// Decodes one whole frame; the envelope stays valid while `frame` lives.
const Envelope* decodeOne(const std::vector<uint8_t>& bytes, std::vector<uint8_t>& frame) {
  FrameDecoder decoder;
  EXPECT_TRUE(decoder.feed(bytes));
  auto f = decoder.next();
  if (!f) return nullptr;
  frame = std::move(*f);
  return envelopeOf(frame);
}

TEST(CellReady, CarriesEveryCellThatBecameReadyInOneFrameInOrder) {
  const std::vector<glm::ivec3> cells = {{3, 0, 7}, {4, 0, 7}, {-1, 2, 1 << 30}};
  std::vector<uint8_t> frame;
  const Envelope* e = decodeOne(encodeCellReady(cells), frame);
  ASSERT_NE(e, nullptr);
  ASSERT_EQ(e->payload_type(), Payload::CellReady);
  EXPECT_EQ(readyCells(*e->payload_as_CellReady()), cells);
}

TEST(CellReady, OneFrameForManyCellsCostsLessThanAFrameForEach) {
  std::vector<glm::ivec3> cells;
  for (int i = 0; i < 8; ++i) cells.push_back({i, 0, 2 * i});
  size_t separate = 0;
  for (const glm::ivec3& c : cells) separate += encodeCellReady({c}).size();
  const size_t together = encodeCellReady(cells).size();
  EXPECT_LT(together, separate / 2) << together << " bytes against " << separate;
}

TEST(CellReady, WithoutCellsAnnouncesNothing) {
  std::vector<uint8_t> frame;
  const Envelope* e = decodeOne(encodeCellReady({}), frame);
  ASSERT_NE(e, nullptr);
  EXPECT_TRUE(readyCells(*e->payload_as_CellReady()).empty());
  // A version 2 CellReady (one `cell`, now deprecated) announces nothing
  // either: its only cell sits in a field this version does not read.
  flatbuffers::FlatBufferBuilder b;
  const CellIndex old(1, 2, 3);
  CellReadyBuilder rb(b);
  rb.fbb_.AddStruct(4, &old);  // field 0 (`cell`), as version 2 wrote it
  const auto ready = rb.Finish();
  b.Finish(CreateEnvelope(b, Payload::CellReady, ready.Union()));
  const Envelope* v2 = decodeOne(encodeFrame(b), frame);
  ASSERT_NE(v2, nullptr);
  EXPECT_TRUE(readyCells(*v2->payload_as_CellReady()).empty());
}

TEST(CellReady, ACellListLongerThanItsFrameIsRefusedByTheDecoder) {
  // Claim a million cells in a frame that holds two: the Verifier refuses
  // the frame before anyone reads the vector.
  std::vector<uint8_t> bytes = encodeCellReady({{1, 2, 3}, {4, 5, 6}});
  const std::vector<uint8_t> pattern = {2, 0, 0, 0};  // the vector's length, little-endian
  auto it = std::search(bytes.begin() + 4, bytes.end(), pattern.begin(), pattern.end());
  ASSERT_NE(it, bytes.end());
  it[2] = 0x0F;  // 2 -> 0x000F0002
  FrameDecoder decoder;
  ASSERT_TRUE(decoder.feed(bytes));
  EXPECT_FALSE(decoder.next().has_value());
  EXPECT_EQ(decoder.errorCode(), InputErrorCode::BadFrame);
}

TEST(CellReady, EveryTruncationAndEveryFlippedByteIsRefusedOrDecodedSafely) {
  const std::vector<uint8_t> good = encodeCellReady({{1, 2, 3}, {4, 5, 6}, {7, 8, 9}});
  for (size_t cut = 0; cut < good.size(); ++cut) {
    // A shorter length prefix: the frame ends early.
    std::vector<uint8_t> bytes(good.begin(), good.begin() + long(cut));
    if (cut >= 4) {
      const uint32_t n = uint32_t(cut - 4);
      for (int k = 0; k < 4; ++k) bytes[size_t(k)] = uint8_t(n >> (8 * k));
    }
    FrameDecoder decoder;
    decoder.feed(bytes);
    if (auto f = decoder.next()) readyCells(*envelopeOf(*f)->payload_as_CellReady());
  }
  for (size_t i = 4; i < good.size(); ++i)
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xFF)}) {
      std::vector<uint8_t> bytes = good;
      bytes[i] ^= flip;
      FrameDecoder decoder;
      decoder.feed(bytes);
      if (auto f = decoder.next()) {
        const Envelope* e = envelopeOf(*f);
        if (e->payload_type() == Payload::CellReady) {
          EXPECT_LE(readyCells(*e->payload_as_CellReady()).size(), good.size() / 12);
        }
      }
    }
}

}  // namespace
}  // namespace vistream::wire
