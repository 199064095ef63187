#include "server/bake/checked_file.h"

#include <cstring>

#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "server/visibility/pvs_database.h"  // fnv1a64

namespace vistream {
namespace {

void putU32(uint8_t* p, uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
void putU64(uint8_t* p, uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
uint32_t getU32(const uint8_t* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= uint32_t(p[i]) << (8 * i);
  return v;
}
uint64_t getU64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(p[i]) << (8 * i);
  return v;
}

}  // namespace

void writeCheckedFile(const std::filesystem::path& path, const std::array<char, 8>& magic,
                      uint32_t version, std::span<const uint8_t> payload) {
  uint8_t header[kCheckedFileHeaderBytes] = {};
  std::memcpy(header, magic.data(), 8);
  putU32(header + 8, version);
  putU64(header + 16, payload.size());
  putU64(header + 24, fnv1a64(payload.data(), payload.size()));

  AtomicFile file(path);
  file.write(header);
  file.write(payload);
  file.commit(Durability::Synced);
}

bool CheckedFile::checksumOk() const {
  const auto p = payload();
  return fnv1a64(p.data(), p.size()) == checksum;
}

CheckedFile openCheckedFile(const std::filesystem::path& path, const std::array<char, 8>& magic,
                            uint32_t version, std::string_view what, std::string_view versionHint) {
  CheckedFile f;
  f.file = MappedFile::open(path, what);
  const std::string name = path.string();
  const size_t size = f.file.size();
  const char* article =
      !what.empty() && std::string_view("aeiou").find(what[0]) != std::string_view::npos ? "an"
                                                                                         : "a";
  if (size < kCheckedFileHeaderBytes)
    throwInputError("{}: not {} {} (only {} bytes)", name, article, what, size);
  const uint8_t* p = f.file.data();
  if (std::memcmp(p, magic.data(), 8) != 0)
    throwInputError("{}: not {} {} (bad magic)", name, article, what);
  f.version = getU32(p + 8);
  if (f.version != version)
    throwInputError("{}: {} format version {} is not supported (this build reads version {}){}",
                    name, what, f.version, version, versionHint);
  const uint64_t payload = getU64(p + 16);
  if (payload != size - kCheckedFileHeaderBytes)
    throwInputError("{}: truncated or padded: header says {} payload bytes, file has {}", name,
                    payload, size - kCheckedFileHeaderBytes);
  f.checksum = getU64(p + 24);
  return f;
}

}  // namespace vistream
