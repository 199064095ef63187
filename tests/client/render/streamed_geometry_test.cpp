// StreamedGeometry against a plain map of the faces held: after adds,
// evictions, faces sent again and a delta that replaces everything, the live
// triangles (compacted()) are exactly the faces held, each with its latest
// corners, and the slots a change names are exactly those that left.
#include "client/render/streamed_geometry.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

namespace vistream {
namespace {

// A delta adding the given faces, each with `triangles` triangles whose
// corners encode (face, version).
GeometryDelta adding(const std::map<uint32_t, int>& faces, int triangles = 2) {
  GeometryDelta d;
  for (const auto& [face, version] : faces)
    for (int t = 0; t < triangles; ++t) {
      const glm::vec3 p{float(face), float(version), float(t)};
      d.added.triangles.positions.insert(d.added.triangles.positions.end(),
                                         {p, p + glm::vec3(1, 0, 0), p + glm::vec3(0, 0, 1)});
      d.added.triangles.faceIds.push_back(face);
      d.added.triangles.objectIds.push_back(0);
      d.added.triangles.degenerate.push_back(0);
      d.added.lighting.appendFlat(glm::u8vec3(uint8_t(face), uint8_t(version), 0));
    }
  return d;
}

// The live triangles as (face, version) per triangle, from their corners.
std::multimap<uint32_t, int> liveOf(const StreamedGeometry& s) {
  std::multimap<uint32_t, int> out;
  const RenderGeometry g = s.compacted();
  for (size_t t = 0; t < g.size(); ++t) {
    EXPECT_EQ(uint32_t(g.triangles.vertex(t, 0).x), g.triangles.faceIds[t]);
    out.emplace(g.triangles.faceIds[t], int(g.triangles.vertex(t, 0).y));
  }
  return out;
}

std::multimap<uint32_t, int> expected(const std::map<uint32_t, int>& held) {
  std::multimap<uint32_t, int> out;
  for (const auto& [face, version] : held) out.insert({{face, version}, {face, version}});
  return out;
}

TEST(StreamedGeometry, HoldsExactlyTheLatestCopyOfEveryFaceNotEvicted) {
  std::mt19937 rng(11);
  StreamedGeometry s;
  std::map<uint32_t, int> held;
  std::uniform_int_distribution<uint32_t> anyFace(0, 60);
  for (int step = 1; step < 40; ++step) {
    std::map<uint32_t, int> sent;
    for (int k = 0; k < 6; ++k) sent[anyFace(rng)] = step;  // new or sent again
    GeometryDelta d = adding(sent);
    for (int k = 0; k < 3; ++k) {
      const uint32_t f = anyFace(rng);
      if (!sent.count(f)) d.removed.push_back(f);  // some never held: ignored
    }
    const size_t sizeBefore = s.geometry().size();
    std::set<uint32_t> leaving;
    for (const uint32_t f : d.removed)
      if (held.count(f)) leaving.insert(f);
    for (const auto& [f, v] : sent)
      if (held.count(f)) leaving.insert(f);
    const GeometryChange change = s.apply(d);
    EXPECT_EQ(change.firstAdded, sizeBefore);
    EXPECT_EQ(change.removed.size(), 2 * leaving.size());
    for (const uint32_t slot : change.removed) {
      EXPECT_FALSE(s.live(slot));
      EXPECT_TRUE(leaving.count(s.geometry().triangles.faceIds[slot]));
    }
    for (const uint32_t f : d.removed) held.erase(f);
    for (const auto& [f, v] : sent) held[f] = v;
    ASSERT_EQ(liveOf(s), expected(held)) << "step " << step;
    EXPECT_EQ(s.faces(), held.size());
    EXPECT_EQ(s.liveTriangles(), 2 * held.size());
    if (step % 10 == 0) {
      s.compact();
      EXPECT_EQ(s.deadTriangles(), 0u);
      ASSERT_EQ(liveOf(s), expected(held));
    }
  }
  // A delta that replaces everything.
  GeometryDelta all = adding({{7, 99}});
  all.replaceAll = true;
  const GeometryChange change = s.apply(all);
  EXPECT_EQ(change.removed.size(), 2 * held.size());
  EXPECT_EQ(liveOf(s), expected({{7, 99}}));
}

}  // namespace
}  // namespace vistream
