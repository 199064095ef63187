// Face-ID ranges (Hello.held_faces): what is written reads back, against a
// brute-force list of IDs; every malformed list is refused naming the field.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "protocol/geometry/byte_coding.h"

namespace vistream::wire {
namespace {

std::vector<uint32_t> roundTrip(const std::vector<uint32_t>& ids, uint64_t limit, size_t maxIds,
                                std::string* error = nullptr) {
  std::vector<uint8_t> bytes;
  putIdRanges(bytes, ids);
  PayloadReader r(bytes);
  std::vector<uint32_t> out;
  const bool ok = readIdRanges(r, limit, maxIds, "held", out);
  if (error) *error = r.error();
  EXPECT_EQ(ok, r.error().empty());
  return ok ? out : std::vector<uint32_t>{0xFFFFFFFFu};
}

TEST(IdRanges, RandomSetsReadBackAsWritten) {
  std::mt19937 random(7);
  for (int trial = 0; trial < 200; ++trial) {
    std::set<uint32_t> set;
    const uint32_t limit = 1 + random() % 100000;
    const int runs = int(random() % 50);
    for (int k = 0; k < runs; ++k) {
      const uint32_t first = random() % limit, length = 1 + random() % 40;
      for (uint32_t id = first; id < std::min(limit, first + length); ++id) set.insert(id);
    }
    const std::vector<uint32_t> ids(set.begin(), set.end());
    EXPECT_EQ(roundTrip(ids, limit, ids.size()), ids) << "trial " << trial;
  }
}

TEST(IdRanges, ConsecutiveFacesCostAFewBytesARun) {
  std::vector<uint32_t> ids;
  for (uint32_t b = 0; b < 100; ++b)  // 100 buildings of 60 faces, 40 apart
    for (uint32_t f = 0; f < 60; ++f) ids.push_back(b * 100 + f);
  std::vector<uint8_t> bytes;
  putIdRanges(bytes, ids);
  EXPECT_LE(bytes.size(), 2u + 100u * 2u);  // count, then 1-byte gaps and lengths
  EXPECT_EQ(roundTrip(ids, 10000, ids.size()), ids);
}

TEST(IdRanges, EdgesReadBack) {
  EXPECT_EQ(roundTrip({}, 10, 10), std::vector<uint32_t>{});
  EXPECT_EQ(roundTrip({0}, 1, 1), std::vector<uint32_t>{0});
  EXPECT_EQ(roundTrip({9}, 10, 1), std::vector<uint32_t>{9});
  EXPECT_EQ(roundTrip({0, 1, 2, 5, 9}, 10, 5), (std::vector<uint32_t>{0, 1, 2, 5, 9}));
}

TEST(IdRanges, IdsAtTheLimitOrTooManyAreRefusedNamingTheField) {
  std::string error;
  roundTrip({3, 10}, 10, 10, &error);
  EXPECT_NE(error.find("held"), std::string::npos) << error;
  roundTrip({0, 1, 2, 3}, 10, 3, &error);
  EXPECT_NE(error.find("more than 3"), std::string::npos) << error;
  // A range running past the limit: one range of 5 from 8.
  std::vector<uint8_t> bytes;
  putVarint(bytes, 1);
  putVarint(bytes, 8);
  putVarint(bytes, 4);
  PayloadReader r(bytes);
  std::vector<uint32_t> out;
  EXPECT_FALSE(readIdRanges(r, 10, 100, "held", out));
  EXPECT_NE(r.error().find("held"), std::string::npos);
  // Cut off after the count.
  std::vector<uint8_t> cut;
  putVarint(cut, 2);
  putVarint(cut, 0);
  PayloadReader r2(cut);
  EXPECT_FALSE(readIdRanges(r2, 10, 100, "held", out));
  EXPECT_NE(r2.error().find("cut off"), std::string::npos) << r2.error();
}

}  // namespace
}  // namespace vistream::wire
