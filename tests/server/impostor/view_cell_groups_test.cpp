// View cells merged along streets (server/impostor/view_cell_groups.h): every
// free cell lands in exactly one straight run of adjacent cells along its
// street, no longer than asked and cut evenly; the answers for a small
// street map are worked out by hand.
#include "server/impostor/view_cell_groups.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <string>

#include "common/core/error.h"

namespace vistream {
namespace {

// A one-layer grid of 12 x 1 x 8 cells of 4 m and its free cells drawn as a
// map (rows are z, columns x; '#' free):
//   z=0  #########...   a street along X, 9 cells
//   z=1  ...#........   a street along Z, 5 cells long (z=1..5), 1 wide
//   z=2  ...#........
//   z=3  ...#.....#..   a lone cell at x=9
//   z=4  ...#........
//   z=5  ...#........
//   z=6  ........##..   a 2 x 2 plaza: lines of 2 both ways, so along X
//   z=7  ........##..
struct StreetMap {
  ViewCellGrid grid{Box3f(glm::vec3(0.0f), glm::vec3(48.0f, 4.0f, 32.0f)), glm::vec3(4.0f)};
  std::vector<uint32_t> cells;
  StreetMap() {
    const std::vector<std::string> rows = {"#########...", "...#........", "...#........",
                                           "...#.....#..", "...#........", "...#........",
                                           "........##..", "........##.."};
    for (int z = 0; z < 8; ++z)
      for (int x = 0; x < 12; ++x)
        if (rows[size_t(z)][size_t(x)] == '#')
          cells.push_back(uint32_t(grid.linearIndex({x, 0, z})));
  }
  uint32_t at(int x, int z) const { return uint32_t(grid.linearIndex({x, 0, z})); }
};

// Every cell given lies in exactly one group, and a group is a straight run
// of adjacent given cells from lo to hi, its leader first.
void expectPartition(const StreetMap& m, const std::vector<ViewCellGroup>& groups,
                     uint32_t maxCells) {
  std::map<uint32_t, int> seen;
  for (const ViewCellGroup& g : groups) {
    ASSERT_FALSE(g.members.empty());
    EXPECT_LE(g.members.size(), maxCells);
    EXPECT_TRUE(std::is_sorted(g.members.begin(), g.members.end()));
    const glm::ivec3 extent = g.hi - g.lo;
    EXPECT_TRUE(extent.y == 0 && (extent.x == 0 || extent.z == 0)) << "not straight";
    EXPECT_EQ(size_t(extent.x + extent.z + 1), g.members.size()) << "not adjacent";
    EXPECT_EQ(g.leader(), m.grid.linearIndex(g.lo));
    EXPECT_EQ(g.members.back(), m.grid.linearIndex(g.hi));
    for (uint32_t c : g.members) ++seen[c];
  }
  EXPECT_EQ(seen.size(), m.cells.size());
  for (uint32_t c : m.cells) EXPECT_EQ(seen[c], 1) << "cell " << c;
}

TEST(ViewCellGroups, CutEachStreetEvenlyIntoRunsNoLongerThanAsked) {
  const StreetMap m;
  const std::vector<ViewCellGroup> groups = mergeViewCells(m.grid, m.cells, 4);
  expectPartition(m, groups, 4);
  std::map<uint32_t, glm::ivec3> hiOf;  // leader -> last cell
  for (const ViewCellGroup& g : groups) hiOf[g.leader()] = g.hi;
  // The X street of 9 cells at most 4: 3, 3, 3 (not 4, 4, 1).
  EXPECT_EQ(hiOf.at(m.at(0, 0)), glm::ivec3(2, 0, 0));
  EXPECT_EQ(hiOf.at(m.at(3, 0)), glm::ivec3(5, 0, 0));
  EXPECT_EQ(hiOf.at(m.at(6, 0)), glm::ivec3(8, 0, 0));
  // (3, 0) has a line of 9 along X and of 6 along Z: it belongs to the X
  // street, and the Z street's 5 remaining cells are cut 3, 2.
  EXPECT_EQ(hiOf.at(m.at(3, 1)), glm::ivec3(3, 0, 3));
  EXPECT_EQ(hiOf.at(m.at(3, 4)), glm::ivec3(3, 0, 5));
  // The lone cell is a view cell of its own; the plaza's rows run along X.
  EXPECT_EQ(hiOf.at(m.at(9, 3)), glm::ivec3(9, 0, 3));
  EXPECT_EQ(hiOf.at(m.at(8, 6)), glm::ivec3(9, 0, 6));
  EXPECT_EQ(hiOf.at(m.at(8, 7)), glm::ivec3(9, 0, 7));
  EXPECT_EQ(groups.size(), 8u);
}

TEST(ViewCellGroups, OneCellPerViewCellWhenAskedForOneAndLongRunsWhenAskedForMore) {
  const StreetMap m;
  const std::vector<ViewCellGroup> single = mergeViewCells(m.grid, m.cells, 1);
  expectPartition(m, single, 1);
  EXPECT_EQ(single.size(), m.cells.size());
  const std::vector<ViewCellGroup> long_ = mergeViewCells(m.grid, m.cells, 16);
  expectPartition(m, long_, 16);
  // The X street whole, the Z street's 5, the lone cell, the plaza's 2 rows.
  EXPECT_EQ(long_.size(), 5u);
  // Duplicates in the input are one cell.
  std::vector<uint32_t> twice = m.cells;
  twice.insert(twice.end(), m.cells.begin(), m.cells.end());
  EXPECT_EQ(mergeViewCells(m.grid, twice, 4).size(), 8u);
}

TEST(ViewCellGroups, RefusesZeroCellsAndCellsOutsideTheGrid) {
  const StreetMap m;
  EXPECT_THROW(mergeViewCells(m.grid, m.cells, 0), InputError);
  try {
    mergeViewCells(m.grid, {uint32_t(m.grid.cellCount())}, 4);
    ADD_FAILURE() << "a cell outside the grid was merged";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("outside the grid"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(mergeViewCells(m.grid, {}, 4).empty());
}

TEST(ViewCellGroups, TheBoxOfARunSpansItsFirstAndLastCells) {
  const StreetMap m;
  const Box3f box = viewCellBox(m.grid, {3, 0, 1}, {3, 0, 3});
  EXPECT_EQ(box.lo, glm::vec3(12.0f, 0.0f, 4.0f));
  EXPECT_EQ(box.hi, glm::vec3(16.0f, 4.0f, 16.0f));
}

}  // namespace
}  // namespace vistream
