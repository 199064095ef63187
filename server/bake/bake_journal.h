// The journal of a resumable bake: every finished cell is appended as one
// record with its own checksum, so a bake killed at any moment (or a disk
// that corrupts a block) loses at most the cells whose records are not
// intact, and a restarted bake with the same parameters computes only what
// is missing. The PVS bake (server/visibility/pvs_bake.h) and the impostor
// bake (server/impostor/impostor_database.h) keep one each.
//
// File layout (host byte order): an 8-byte magic naming the bake and its
// journal format, the bake's fingerprint (8 bytes: everything that changes
// its answer), then records
//   [cell index u32][aux u32][payload bytes u32][payload][FNV-1a 64 of the 12 + payload bytes]
// `aux` is the bake's own (the PVS bake: the face count).
//
// Reading back takes the valid prefix: every record up to the first one that
// is incomplete (a torn write), fails its checksum, or that the bake's
// reader refuses (a cell outside its grid, a payload that does not decode).
// That record and everything after it are dropped, never trusted, and a
// warning names the journal, the offset and how many bytes and records were
// dropped; the file is cut to the prefix so appends continue cleanly. A
// journal of another magic or fingerprint is started over, with a warning.
//
// Thread safety: append() may be called from several threads at once.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <span>
#include <string>

namespace vistream {

struct JournalRecordView {
  uint32_t index = 0, aux = 0;
  std::span<const uint8_t> payload;
};

class BakeJournal {
 public:
  // Takes a valid record of the existing prefix: returns an empty string to
  // accept it (and keeps what it needs), or why it is refused.
  using RecordReader = std::function<std::string(const JournalRecordView&)>;

  // Opens (creating if needed) the journal at `path`; a journal with this
  // magic and fingerprint is read back through `reader` first.
  BakeJournal(const std::filesystem::path& path, const std::array<char, 8>& magic,
              uint64_t fingerprint, const RecordReader& reader);
  ~BakeJournal();
  BakeJournal(const BakeJournal&) = delete;
  BakeJournal& operator=(const BakeJournal&) = delete;

  // Appends one finished cell (thread-safe). Throws InputError if the write fails.
  void append(uint32_t index, uint32_t aux, std::span<const uint8_t> payload);
  // Closes and deletes the journal (the bake's output is written).
  void remove();
  // Records taken from an existing journal.
  size_t resumed() const { return resumed_; }

 private:
  void writeAll(const void* data, size_t n);
  void readExisting(const std::array<char, 8>& magic, uint64_t fingerprint,
                    const RecordReader& reader);

  std::filesystem::path path_;
  int fd_ = -1;
  size_t resumed_ = 0;
  std::mutex mutex_;  // guards appends to fd_
};

}  // namespace vistream
