// The baked PVS database: one file holding the PVS of every view cell of a
// grid over a scene's free space.
//
// File layout (all little-endian):
//   bytes  0..7   magic "VSPVSDB\0"
//   bytes  8..11  format version (kPvsDbVersion)
//   bytes 12..15  reserved, zero
//   bytes 16..23  payload size in bytes
//   bytes 24..31  FNV-1a 64 checksum of the payload
//   bytes 32..    payload: a FlatBuffer with root pvsdb::Database
//                 (server/visibility/pvs_database.fbs)
// The payload starts 8-byte aligned, so the file can be memory-mapped and
// read in place. Files are written to NAME.tmp and renamed: a crash never
// leaves a torn database. Opening checks magic, version, size, checksum and
// runs the FlatBuffers verifier; any failure is an InputError naming the file
// and what is wrong.
//
// Thread safety: a PvsDatabase is immutable once opened; lookups may run
// concurrently.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "common/scene/scene.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

inline constexpr uint32_t kPvsDbVersion = 1;

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

// Encodes sorted face IDs as delta LEB128 varints, and back. decode throws
// InputError on malformed bytes (it reads untrusted files).
std::vector<uint8_t> encodeFaceList(const std::vector<uint32_t>& sortedFaces);
std::vector<uint32_t> decodeFaceList(const uint8_t* data, size_t size, uint32_t expectedCount);

// Writes a database atomically. `cells` maps linear cell index to sorted faces.
void writePvsDatabase(const std::filesystem::path& path, const PvsDatabaseHeader& header,
                      const std::map<uint32_t, std::vector<uint32_t>>& cells);

class PvsDatabase {
 public:
  // Memory-maps and validates the file. Throws InputError.
  static PvsDatabase open(const std::filesystem::path& path);
  PvsDatabase(PvsDatabase&&) noexcept;
  PvsDatabase& operator=(PvsDatabase&&) noexcept;
  ~PvsDatabase();

  const PvsDatabaseHeader& header() const { return header_; }
  size_t cellCount() const;
  // The PVS of a cell, or nothing if the cell was not baked.
  std::optional<std::vector<uint32_t>> cell(uint32_t linearIndex) const;
  // Every baked cell's linear index, ascending.
  std::vector<uint32_t> cellIndices() const;
  const std::filesystem::path& path() const { return path_; }

 private:
  PvsDatabase() = default;
  std::filesystem::path path_;
  const uint8_t* map_ = nullptr;
  size_t mapSize_ = 0;
  const void* root_ = nullptr;  // const pvsdb::Database*
  PvsDatabaseHeader header_;
};

}  // namespace vistream
