// The envelope of a baked database (the PVS database, the impostor
// database): a 32-byte header, then the payload, memory-mapped and read in
// place.
//
//   bytes  0..7   magic (8 bytes, naming the kind of file)
//   bytes  8..11  format version
//   bytes 12..15  reserved, zero
//   bytes 16..23  payload size in bytes
//   bytes 24..31  FNV-1a 64 checksum of the payload (fnv1a64)
//   bytes 32..    payload (8-byte aligned in the mapping)
// All little-endian. Files are written through AtomicFile (a unique
// temporary, fsynced and renamed): a crash never leaves a torn database.
//
// Thread safety: free functions; a CheckedFile is immutable once opened.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>

#include "common/core/mapped_file.h"

namespace vistream {

inline constexpr size_t kCheckedFileHeaderBytes = 32;

// Writes header and payload atomically. Throws InputError naming the file
// when it cannot be written.
void writeCheckedFile(const std::filesystem::path& path, const std::array<char, 8>& magic,
                      uint32_t version, std::span<const uint8_t> payload);

struct CheckedFile {
  MappedFile file;
  uint32_t version = 0;
  uint64_t checksum = 0;  // as the header states it

  std::span<const uint8_t> payload() const { return file.bytes().subspan(kCheckedFileHeaderBytes); }
  // Whether the payload matches the header's checksum (one pass over it).
  bool checksumOk() const;
};

// Maps the file and checks its magic, version and size (not the checksum:
// callers run checksumOk() beside their own pass over the payload). Throws
// InputError naming the file and `what` it should be ("PVS database");
// `versionHint` follows the message for an unsupported version ("; re-bake it").
CheckedFile openCheckedFile(const std::filesystem::path& path, const std::array<char, 8>& magic,
                            uint32_t version, std::string_view what,
                            std::string_view versionHint = {});

}  // namespace vistream
