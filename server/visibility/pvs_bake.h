// Baking the PVS of every view cell of a grid over a scene's free space.
//
// Cells: a regular grid (ViewCellGrid) over the region (default: the scene's
// bounds in X and Z, and from the lowest walkable floor to 2.5 m above the
// highest in Y). A cell is baked when some walkable column of the free space
// under it has a viewer's eye range (0.2 m to 2.0 m above the floor) reaching
// into the cell: cells inside buildings or in the sky are skipped.
//
// Coarse to fine (Cohen-Or and Zadicario 1998, section 4): cells are baked in
// blocks of 2 x 1 x 2; the block's PVS is computed first and its cells only
// test the faces in it.
//
// Resumable: every finished cell is appended to a journal (OUT.journal) with
// its own checksum; a restarted bake with the same parameters (fingerprinted
// in the journal's header) reads the journal's valid prefix and computes only
// what is missing. The prefix ends at the first record that is incomplete (a
// torn write) or fails its checksum, names a cell outside the grid or holds a
// bad face list; that record and everything after it are dropped and
// recomputed, never trusted, and a warning names the journal, the offset and
// how many bytes and records were dropped. A resumed bake writes the same
// database, byte for byte, as one run straight through (the coarse level is
// always the whole block's PVS). The database itself is written atomically at
// the end (pvs_database.h) and the journal removed.
//
// Sharding: shard i of n bakes the blocks whose index is i modulo n; shards
// baked on separate machines are combined with mergePvsDatabases().
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/world/free_space.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/pvs_database.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

struct BakeOptions {
  glm::vec3 cellSize{4.0f, 4.0f, 4.0f};
  std::optional<Box3f> region;  // local frame; default derived from the free space
  unsigned threads = 0;         // 0: all cores
  uint32_t shardIndex = 0, shardCount = 1;
  bool coarseToFine = true;
  PvsOptions pvs;
  std::function<void(size_t done, size_t total)> progress;  // called from worker threads
};

struct BakeReport {
  size_t gridCells = 0;     // cells in the grid
  size_t freeCells = 0;     // cells over the free space (all shards)
  size_t shardCells = 0;    // cells this shard bakes
  size_t resumedCells = 0;  // this shard's cells taken from the journal
  size_t computedCells = 0;
  double timeMs = 0.0;
  double meanCellMs = 0.0;  // per computed cell, wall time x threads / cells
  uint64_t totalFaces = 0;  // sum of PVS sizes of this shard's cells
};

// The grid and the free-space cells a bake would use (shared by bake and tests).
ViewCellGrid bakeGrid(const Scene& scene, const FreeSpace& freeSpace, const BakeOptions& options);
std::vector<uint32_t> freeSpaceCells(const Scene& scene, const ViewCellGrid& grid,
                                     const FreeSpace& freeSpace);

BakeReport bakePvs(const Scene& scene, const EpsilonPvs& pvs, const FreeSpace& freeSpace,
                   const BakeOptions& options, const std::filesystem::path& out);

// Merges shard databases of one scene, grid and method into one. Throws
// InputError naming the file that does not match the first.
void mergePvsDatabases(const std::vector<std::filesystem::path>& inputs,
                       const std::filesystem::path& out);

}  // namespace vistream
