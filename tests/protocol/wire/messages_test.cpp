// The one mapping from InputError codes to the wire's ErrorCode, and the
// codes the frame decoder gives its failures.
#include "protocol/wire/messages.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace vistream::wire
