// A read-only memory mapping of a whole regular file.
//
// Used for files read in place (PVS databases, bake journals). Untrusted
// input: a path that cannot be opened, is not a regular file or cannot be
// mapped throws InputError naming the file and `what` it was meant to be.
// An empty file maps to an empty span. Move-only; the mapping lives until
// the object is destroyed. Thread safety: const access from any thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>

namespace vistream {

class MappedFile {
 public:
  MappedFile() = default;
  // `what` names the file's role in messages ("PVS database").
  static MappedFile open(const std::filesystem::path& path, std::string_view what);
  MappedFile(MappedFile&& o) noexcept;
  MappedFile& operator=(MappedFile&& o) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  ~MappedFile();

  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }
  std::span<const uint8_t> bytes() const { return {data_, size_}; }

 private:
  void release();
  const uint8_t* data_ = nullptr;
  size_t size_ = 0;
};

}  // namespace vistream
