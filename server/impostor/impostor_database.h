// The impostor database: the impostors of every view cell of a baked PVS
// database (vistream-pvs impostors --db PVS.db --out IMP.db), for the
// streaming server to send.
//
// File: the checked envelope of server/bake/checked_file.h (magic
// "VSIMPDB\0", version kImpostorDbVersion, size, FNV-1a checksum), then a
// FlatBuffer with root impdb::Database (impostor_database.fbs): the scene's
// identity and the PVS database's grid, the bake's settings (JSON and their
// fingerprint), and per cell one record (CellRecord, below): why the cell
// got impostors or none, and per impostor its sector and band, the faces it
// replaces (face IDs: the geometry a client no longer needs beyond d), its
// encoded bytes (protocol/impostor) and its figures, then the faces of the
// sites left as geometry (the far field the server streams as faces). A cell the bake visited
// is present even with no impostor, so "not baked" and "nothing to replace"
// stay apart.
//
// Opening validates everything but the impostors' own bytes: envelope,
// checksum, FlatBuffers verifier, grid, cell indices, and every record's
// structure and face lists, and its view cell: inside the grid, holding the
// cell, its leader present with the same range, and a non-leader's record
// empty (InputError naming the file and cell). An
// impostor's bytes are decoded when used; should that fail (the file changed
// after it was opened), the cell is reported as not baked with an error logged.
//
// Baking (bakeImpostorDatabase) is resumable through a bake journal
// (server/bake/bake_journal.h; OUT.journal), and writes the database
// atomically at the end.
//
// Thread safety: an ImpostorDatabase is immutable once opened; lookups may
// run concurrently.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <glm/glm.hpp>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/core/mapped_file.h"
#include "common/impostor/impostor.h"
#include "server/impostor/impostor_world.h"
#include "server/visibility/pvs_database.h"

namespace vistream {

// 2: impostor encoding version 2; 3: records hold the faces of sites left as
// geometry; 4: records name their view cell (cells merged along streets).
inline constexpr uint32_t kImpostorDbVersion = 4;

// One impostor of a cell as stored.
struct StoredImpostor {
  uint32_t sector = 0, band = 0;
  std::vector<uint32_t> faces;  // replaced faces, ascending
  std::vector<uint8_t> bytes;   // protocol/impostor encoding
  // Its figures (no times: a resumed bake writes the same bytes as one run
  // straight through).
  uint64_t points = 0, screenPixels = 0, coveredPixels = 0, geometryBytes = 0;
};

// A cell's record: why, its impostors, and the faces of its sites left as
// geometry (CellImpostors::geometryFaces), which a client that asks for
// impostors receives whatever its near-field radius; and the view cell they
// were baked for, the grid cells viewLo..viewHi (view_cell_groups.h). The
// view cell's first cell (its leader, viewLo) holds the impostors and the
// faces; every other cell of it holds only the range and a why naming the
// leader (no impostors, no faces), and is served the leader's record.
struct CellRecord {
  std::string why;
  std::vector<StoredImpostor> impostors;
  std::vector<uint32_t> geometryFaces;  // ascending
  glm::ivec3 viewLo{0}, viewHi{0};      // grid indices, inclusive
};
std::vector<uint8_t> encodeCellRecord(const CellRecord& record);
// Throws InputError (starting "cell record") unless the bytes are one
// well-formed record whose face IDs lie below `faceLimit`.
CellRecord decodeCellRecord(std::span<const uint8_t> bytes, uint32_t faceLimit);

struct ImpostorDatabaseHeader {
  PvsDatabaseHeader pvs;  // scene and grid of the PVS database baked from
  std::string settings;   // JSON
  uint64_t settingsFingerprint = 0;
};

void writeImpostorDatabase(const std::filesystem::path& path, const ImpostorDatabaseHeader& header,
                           const std::map<uint32_t, std::vector<uint8_t>>& records);

class ImpostorDatabase {
 public:
  // Memory-maps and validates the file (see above). Throws InputError.
  static ImpostorDatabase open(const std::filesystem::path& path);
  ImpostorDatabase(ImpostorDatabase&&) noexcept = default;
  ImpostorDatabase& operator=(ImpostorDatabase&&) noexcept = default;

  const ImpostorDatabaseHeader& header() const { return header_; }
  size_t cellCount() const { return index_.size(); }
  std::vector<uint32_t> cellIndices() const;
  // The cell's record as stored, or nothing if the bake did not visit it.
  std::optional<CellRecord> cell(uint32_t linearIndex) const;
  // The leader of the view cell holding the cell (the cell itself when it
  // is its own view cell), or nothing if the bake did not visit it.
  std::optional<uint32_t> viewCellOf(uint32_t linearIndex) const;
  const std::filesystem::path& path() const { return path_; }

 private:
  ImpostorDatabase() = default;
  std::filesystem::path path_;
  MappedFile file_;
  ImpostorDatabaseHeader header_;
  std::map<uint32_t, std::span<const uint8_t>> index_;  // cell -> its record in the mapping
  std::map<uint32_t, uint32_t> leaders_;                // cell -> its view cell's leader
};

struct ImpostorBakeOptions {
  ImpostorPlacementOptions placement;
  ImpostorOptions impostor;
  std::optional<Box3f> region;  // local frame: only cells overlapping it
  // View cells: up to this many grid cells merged along a street
  // (view_cell_groups.h); 1 bakes every grid cell on its own.
  uint32_t mergeCells = 4;
  // Bake only shard shardIndex of shardCount: the view cells (of the
  // region's cells, in their leaders' order) at positions shardIndex,
  // shardIndex + shardCount, ...;
  // mergeImpostorDatabases joins the shards into one-process bytes.
  uint32_t shardIndex = 0, shardCount = 1;
  unsigned threads = 0;  // 0: all cores
  std::string settings;  // JSON of the options, stored in the database
  std::function<void(size_t done, size_t total)> progress;  // from worker threads
};

struct ImpostorBakeReport {
  size_t cells = 0, resumedCells = 0, computedCells = 0;
  size_t viewCells = 0;  // the cells merged into view cells (mergeCells)
  // Cells whose view cell has impostors, those view cells, and the sums
  // over view cells (each counted once, however many cells it merges).
  size_t cellsWithImpostors = 0, viewCellsWithImpostors = 0, impostors = 0;
  uint64_t points = 0, bytes = 0, geometryBytes = 0;
  uint64_t geometryFaces = 0;  // of the sites left as geometry
  double timeMs = 0.0;
};

// Bakes the impostors of every cell of `pvs` (within the region and shard)
// into `out`. Throws InputError when the database does not belong to the
// world's scene or the shard is not i/n with i < n.
ImpostorBakeReport bakeImpostorDatabase(const ImpostorWorld& world, const PvsDatabase& pvs,
                                        const ImpostorBakeOptions& options,
                                        const std::filesystem::path& out);

// Joins shard databases baked from one PVS database with one set of
// settings; a cell in two inputs must hold the same record. Throws
// InputError naming the input that does not match the first.
void mergeImpostorDatabases(const std::vector<std::filesystem::path>& inputs,
                            const std::filesystem::path& out);

}  // namespace vistream
