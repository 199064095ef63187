// The ImpostorData message (protocol/impostor/impostor_message.h): what is
// encoded reads back field for field, and a receiver refuses values out of
// range (index, count, replaced faces, the view cell's last cell) naming the field.
#include "protocol/impostor/impostor_message.h"

#include <gtest/gtest.h>

#include "protocol/geometry/byte_coding.h"
#include "protocol/wire/messages.h"

namespace vistream::wire {
namespace {

ImpostorMessage sample() {
  ImpostorMessage m;
  m.cell = {3, 0, -2};
  m.index = 1;
  m.count = 4;
  m.why = "heavy far field";
  m.sector = 5;
  m.band = 2;
  m.replacedFaces = {0, 7, 7, 300, 100'000};
  m.data = {1, 2, 3, 250};
  return m;
}

// Encodes, frames, verifies and reads back.
bool roundTrip(const ImpostorMessage& m, uint32_t faceLimit, ImpostorMessage& out,
               std::string& error) {
  const std::vector<uint8_t> frame = encodeImpostorMessage(m);
  FrameDecoder decoder(1u << 20);
  decoder.feed(frame);
  const auto bytes = decoder.next();
  EXPECT_TRUE(bytes);
  const Envelope* e = envelopeOf(*bytes);
  EXPECT_TRUE(e && e->payload_type() == Payload::ImpostorData);
  return readImpostorMessage(*e->payload_as_ImpostorData(), faceLimit, out, error);
}

TEST(ImpostorMessage, ReadsBackEveryFieldAsEncoded) {
  const ImpostorMessage m = sample();
  ImpostorMessage out;
  std::string error;
  ASSERT_TRUE(roundTrip(m, 200'000, out, error)) << error;
  EXPECT_EQ(out.cell, m.cell);
  EXPECT_EQ(out.index, 1u);
  EXPECT_EQ(out.count, 4u);
  EXPECT_EQ(out.why, m.why);
  EXPECT_EQ(out.sector, 5u);
  EXPECT_EQ(out.band, 2u);
  EXPECT_EQ(out.replacedFaces, m.replacedFaces);
  EXPECT_EQ(out.data, m.data);
  EXPECT_FALSE(out.cellHi.has_value());  // one grid cell
  EXPECT_EQ(out.last(), m.cell);
}

TEST(ImpostorMessage, AViewCellOfMergedCellsReadsBackItsLastCell) {
  ImpostorMessage m = sample();
  m.cellHi = glm::ivec3(3, 0, 1);
  ImpostorMessage out;
  std::string error;
  ASSERT_TRUE(roundTrip(m, 200'000, out, error)) << error;
  EXPECT_EQ(out.cell, m.cell);
  EXPECT_EQ(out.last(), glm::ivec3(3, 0, 1));
}

TEST(ImpostorMessage, ACellWithoutImpostorsCarriesOnlyItsReason) {
  ImpostorMessage m;
  m.cell = {1, 1, 1};
  m.why = "far field lighter than the threshold";
  ImpostorMessage out;
  std::string error;
  ASSERT_TRUE(roundTrip(m, 10, out, error)) << error;
  EXPECT_EQ(out.count, 0u);
  EXPECT_TRUE(out.data.empty());
  EXPECT_EQ(out.why, m.why);
}

TEST(ImpostorMessage, RefusesValuesOutOfRangeNamingTheField) {
  struct Case {
    const char* name;
    void (*change)(ImpostorMessage&);
    uint32_t faceLimit;
    const char* expected;
  };
  const Case cases[] = {
      {"index not below count", [](ImpostorMessage& m) { m.index = 4; }, 200'000, "index 4"},
      {"count above the bound", [](ImpostorMessage& m) { m.count = kMaxImpostorsPerCell + 1; },
       200'000, "count"},
      {"no impostors but data", [](ImpostorMessage& m) { m.count = m.index = 0; }, 200'000,
       "without impostors"},
      {"impostor without data", [](ImpostorMessage& m) { m.data.clear(); }, 200'000,
       "without data"},
      {"a face beyond the scene", [](ImpostorMessage&) {}, 100'000, "replaced face"},
      {"a view cell ending before it starts",
       [](ImpostorMessage& m) { m.cellHi = m.cell - glm::ivec3(0, 0, 1); }, 200'000, "cell_hi"},
  };
  for (const Case& c : cases) {
    ImpostorMessage m = sample();
    c.change(m);
    ImpostorMessage out;
    std::string error;
    EXPECT_FALSE(roundTrip(m, c.faceLimit, out, error)) << c.name;
    EXPECT_NE(error.find(c.expected), std::string::npos) << c.name << ": " << error;
  }
}

TEST(ImpostorMessage, RefusesReplacedFacesThatAreCutOffOrFollowedByBytes) {
  for (const bool cut : {true, false}) {
    ImpostorDataT t;
    t.cell = std::make_unique<CellIndex>(0, 0, 0);
    t.count = 1;
    t.data = {9};
    putVarint(t.replaced_faces, 3);
    putAscending(t.replaced_faces,
                 cut ? std::vector<uint32_t>{1, 2} : std::vector<uint32_t>{1, 2, 3, 4});
    const std::vector<uint8_t> frame = encodeMessage(std::move(t));
    FrameDecoder decoder(1u << 20);
    decoder.feed(frame);
    const auto bytes = decoder.next();
    ASSERT_TRUE(bytes);
    ImpostorMessage out;
    std::string error;
    EXPECT_FALSE(
        readImpostorMessage(*envelopeOf(*bytes)->payload_as_ImpostorData(), 1000, out, error));
    EXPECT_NE(error.find(cut ? "cut off" : "after the replaced faces"), std::string::npos) << error;
  }
}

}  // namespace
}  // namespace vistream::wire
