// The baked PVS database: one file holding the PVS of every view cell of a
// grid over a scene's free space.
//
// File layout (all little-endian):
//   bytes  0..7   magic "VSPVSDB\0"
//   bytes  8..11  format version (kPvsDbVersion)
//   bytes 12..15  reserved, zero
//   bytes 16..23  payload size in bytes
//   bytes 24..31  FNV-1a 64 checksum of the payload (fnv1a64)
//   bytes 32..    payload: a FlatBuffer with root pvsdb::Database
//                 (server/visibility/pvs_database.fbs)
// The payload starts 8-byte aligned, so the file can be memory-mapped and
// read in place. Files are written through AtomicFile (a unique temporary,
// renamed whole): a crash never leaves a torn database.
//
// Versions: 1 had a checksum and scene fingerprint seeded with a wrong FNV
// offset basis (1469598103934665603, one digit short); 2 uses FNV-1a 64 as
// published. Files of any other version are refused with a message saying to
// re-bake.
//
// Opening validates the whole file, so that nothing read later can fail:
// magic, version, size, checksum, the FlatBuffers verifier, the grid, cell
// indices (strictly increasing, inside the grid) and every cell's face list
// (well-formed varints, strictly increasing, as many faces as the cell says,
// every ID below the header's face count). Any failure is an InputError
// naming the file, and for a cell its linear index and i,j,k. Decoding the
// face lists costs a little more CPU than the checksum (each is one pass
// over the bytes): opening a 67 MB bake of city1 (4 m cells, 102,827 cells)
// takes ~200 ms of CPU where version 1 took ~90 ms. The two run side by side,
// and the lists across cores (TBB), so with a second core idle it takes
// ~105 ms of wall time (measured on a 2-core machine).
//
// Thread safety: a PvsDatabase is immutable once opened; lookups may run
// concurrently. The file must not be modified in place while it is open (the
// mapping shares its pages; writers here replace files by rename).
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/core/mapped_file.h"
#include "common/scene/scene.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

inline constexpr uint32_t kPvsDbVersion = 2;

// FNV-1a 64 (Fowler, Noll and Vo): offset basis 14695981039346656037, prime
// 1099511628211. Pass a previous result as `h` to hash data in pieces.
inline constexpr uint64_t kFnv1a64OffsetBasis = 14695981039346656037ull;
uint64_t fnv1a64(const void* data, size_t size, uint64_t h = kFnv1a64OffsetBasis);

// Identifies a scene's geometry (face IDs and positions): a database only
// answers for the scene it was baked from.
uint64_t sceneFingerprint(const Scene& scene);

struct PvsDatabaseHeader {
  std::string sceneName;
  uint64_t sceneFingerprint = 0;
  uint32_t sceneFaces = 0;
  glm::dvec3 origin{0.0};
  glm::vec3 gridLo{0.0f};
  glm::vec3 cellSize{1.0f};
  glm::ivec3 dims{0};
  std::string method = "paper";

  ViewCellGrid grid() const;
  // True if both describe the same scene, grid and method.
  bool compatible(const PvsDatabaseHeader& other) const;
};

// Encodes strictly increasing face IDs as delta LEB128 varints, and back.
// decode reads untrusted bytes: it throws InputError (starting "face list")
// unless the bytes are `expectedCount` well-formed varints of at most 5
// bytes giving strictly increasing IDs, each below `faceLimit` (which is
// capped at 2^32).
std::vector<uint8_t> encodeFaceList(const std::vector<uint32_t>& sortedFaces);
std::vector<uint32_t> decodeFaceList(const uint8_t* data, size_t size, uint32_t expectedCount,
                                     uint64_t faceLimit = uint64_t(1) << 32);

// Writes a database atomically. `cells` maps linear cell index to sorted faces.
void writePvsDatabase(const std::filesystem::path& path, const PvsDatabaseHeader& header,
                      const std::map<uint32_t, std::vector<uint32_t>>& cells);

class PvsDatabase {
 public:
  // Memory-maps and validates the whole file (see the top of this header).
  // Throws InputError naming the file (and the cell, for a bad face list).
  static PvsDatabase open(const std::filesystem::path& path);
  PvsDatabase(PvsDatabase&&) noexcept = default;
  PvsDatabase& operator=(PvsDatabase&&) noexcept = default;

  const PvsDatabaseHeader& header() const { return header_; }
  size_t cellCount() const;
  // The PVS of a cell (sorted face IDs, each below header().sceneFaces), or
  // nothing if the cell was not baked. Never throws InputError: open()
  // validated every list. Should a list fail to decode anyway (the file was
  // modified in place after open), it logs an error naming the file and cell
  // and returns nothing, so callers fall back to computing the PVS.
  std::optional<std::vector<uint32_t>> cell(uint32_t linearIndex) const;
  // Every baked cell's linear index, ascending.
  std::vector<uint32_t> cellIndices() const;
  const std::filesystem::path& path() const { return path_; }

 private:
  PvsDatabase() = default;
  // Verifies the mapped payload and reads the header and every face list
  // (throws InputError).
  void readPayload();
  std::filesystem::path path_;
  MappedFile file_;
  uint64_t checksum_ = 0;       // the header's
  const void* root_ = nullptr;  // const pvsdb::Database*
  PvsDatabaseHeader header_;
};

}  // namespace vistream
