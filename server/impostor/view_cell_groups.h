// View cells for impostors: the bake grid's cells merged along free space
// into street segments (Wimmer 2001, section 5.5: view cells are segments
// of the streets, and one impostor set serves a viewer anywhere along one).
//
// Rule (mergeViewCells). The cells given are those a viewer can stand in
// (the PVS database's cells: the free space's). A cell's street runs along
// the axis, X or Z, on which its line of given cells (same row, same layer,
// no gap) is longer; ties go to X. Each line of cells of one axis is cut,
// from its low end, into segments of at most `maxCells` cells, as even as
// the count allows (9 cells at most 4 give 3, 3, 3, not 4, 4, 1). A cell
// whose two lines are equally short (a plaza's inside, a lone cell) joins
// the run along X. Every given cell lies in exactly one segment; a segment
// is a straight box of adjacent cells, and its first cell (lowest
// coordinates, also its lowest linear index) is its leader: the impostor
// database stores the segment's impostors with the leader and points the
// others at it (impostor_database.h).
//
// Why straight segments: an impostor's shaft runs from the whole view cell
// to its box, and its LDI cameras stand round the shaft's section; a long
// thin segment along the street keeps the section narrow across the street
// and only lengthens it along, where the viewer's own motion is. Why a
// bound: the larger the cell, the wider the shaft (more points survive
// point removal, textures vary more over the sampling plane) and the later
// the first bands start (faces within d of any part of the segment stay
// geometry). The benchmark's table of maxCells against points, bytes, bake
// time and image error (README, "View cells along streets") sets the default.
//
// Thread safety: free functions.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "common/core/box.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

struct ViewCellGroup {
  glm::ivec3 lo{0}, hi{0};        // grid indices, inclusive: a straight run of cells
  std::vector<uint32_t> members;  // linear indices, ascending; members[0] is the leader
  uint32_t leader() const { return members.front(); }
};

// Throws InputError for maxCells 0 or a cell outside the grid. The groups
// come in the order of their leaders.
std::vector<ViewCellGroup> mergeViewCells(const ViewCellGrid& grid,
                                          const std::vector<uint32_t>& cells, uint32_t maxCells);

// The box of the cells lo..hi (inclusive).
Box3f viewCellBox(const ViewCellGrid& grid, const glm::ivec3& lo, const glm::ivec3& hi);

}  // namespace vistream
