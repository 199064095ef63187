#include "server/bake/bake_journal.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "common/core/mapped_file.h"
#include "server/visibility/pvs_database.h"  // fnv1a64

namespace vistream {
namespace {

constexpr size_t kJournalHeaderBytes = 16;  // magic, fingerprint
constexpr size_t kRecordHeadBytes = 12, kRecordSumBytes = 8;
constexpr uint32_t kMaxRecordPayload = 256u << 20;

// One record as read back: Ok, Incomplete (the file ends inside it) or
// Corrupt (complete by its length field, but failing a check).
struct Record {
  enum class Status { Ok, Incomplete, Corrupt } status = Status::Ok;
  size_t end = 0;   // offset just past the record; 0 if its length field is implausible
  std::string why;  // what is wrong, unless Ok
  JournalRecordView view;
};

// The record at `pos` of a journal of `size` bytes, its checksum checked.
Record readRecord(const uint8_t* data, size_t size, size_t pos) {
  Record r;
  if (size - pos < kRecordHeadBytes) {
    r.status = Record::Status::Incomplete;
    r.why = fmt::format("the file ends {} bytes into the record's 12-byte head", size - pos);
    return r;
  }
  uint32_t head[3];
  std::memcpy(head, data + pos, kRecordHeadBytes);
  if (head[2] > kMaxRecordPayload) {
    r.status = Record::Status::Corrupt;
    r.why = fmt::format("its length field says {} bytes", head[2]);
    return r;
  }
  const size_t total = kRecordHeadBytes + head[2] + kRecordSumBytes;
  if (size - pos < total) {
    r.status = Record::Status::Incomplete;
    r.why = fmt::format("the file ends {} bytes into a record of {} bytes", size - pos, total);
    return r;
  }
  r.end = pos + total;
  uint64_t sum = 0;
  std::memcpy(&sum, data + pos + kRecordHeadBytes + head[2], kRecordSumBytes);
  if (fnv1a64(data + pos, kRecordHeadBytes + head[2]) != sum) {
    r.status = Record::Status::Corrupt;
    r.why = "checksum mismatch";
    return r;
  }
  r.view = {head[0], head[1], std::span(data + pos + kRecordHeadBytes, head[2])};
  return r;
}

}  // namespace

BakeJournal::BakeJournal(const std::filesystem::path& path, const std::array<char, 8>& magic,
                         uint64_t fingerprint, const RecordReader& reader)
    : path_(path) {
  if (std::filesystem::exists(path)) readExisting(magic, fingerprint, reader);
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  if (fd_ < 0)
    throwInputError("{}: cannot open bake journal: {}", path.string(), std::strerror(errno));
  if (::lseek(fd_, 0, SEEK_END) == 0) {
    char header[kJournalHeaderBytes];
    std::memcpy(header, magic.data(), 8);
    std::memcpy(header + 8, &fingerprint, 8);
    writeAll(header, sizeof header);
  }
}

BakeJournal::~BakeJournal() {
  if (fd_ >= 0) ::close(fd_);
}

void BakeJournal::append(uint32_t index, uint32_t aux, std::span<const uint8_t> payload) {
  if (payload.size() > kMaxRecordPayload)
    throwInputError("{}: a record of {} bytes is more than a journal holds ({})", path_.string(),
                    payload.size(), kMaxRecordPayload);
  std::vector<uint8_t> rec(kRecordHeadBytes + payload.size() + kRecordSumBytes);
  const uint32_t head[3] = {index, aux, uint32_t(payload.size())};
  std::memcpy(rec.data(), head, kRecordHeadBytes);
  if (!payload.empty()) std::memcpy(rec.data() + kRecordHeadBytes, payload.data(), payload.size());
  const uint64_t sum = fnv1a64(rec.data(), kRecordHeadBytes + payload.size());
  std::memcpy(rec.data() + kRecordHeadBytes + payload.size(), &sum, kRecordSumBytes);
  std::lock_guard lock(mutex_);
  writeAll(rec.data(), rec.size());
}

void BakeJournal::remove() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  std::error_code ec;
  std::filesystem::remove(path_, ec);
}

void BakeJournal::writeAll(const void* data, size_t n) {
  writeAllTo(fd_, {static_cast<const uint8_t*>(data), n}, path_);
}

void BakeJournal::readExisting(const std::array<char, 8>& magic, uint64_t fingerprint,
                               const RecordReader& reader) {
  const std::string name = path_.string();
  const MappedFile file = MappedFile::open(path_, "bake journal");
  const size_t size = file.size();
  const uint8_t* data = file.data();
  size_t valid = 0;
  if (size < kJournalHeaderBytes) {
    spdlog::warn("{}: bake journal is only {} bytes, less than its header; starting over", name,
                 size);
  } else if (std::memcmp(data, magic.data(), 6) == 0 && std::memcmp(data, magic.data(), 8) != 0) {
    spdlog::warn(
        "{}: bake journal of another format (magic '{}', this build writes '{}'); starting over",
        name, std::string(reinterpret_cast<const char*>(data), 7), std::string(magic.data(), 7));
  } else if (std::memcmp(data, magic.data(), 8) != 0) {
    spdlog::warn("{}: not a bake journal (bad magic); starting over", name);
  } else if (std::memcmp(data + 8, &fingerprint, 8) != 0) {
    spdlog::warn("{}: journal is from a bake with other parameters; starting over", name);
  } else {
    valid = kJournalHeaderBytes;
    size_t records = 0;
    Record r;
    while (valid < size) {
      r = readRecord(data, size, valid);
      if (r.status == Record::Status::Ok) {
        std::string why = reader(r.view);
        if (!why.empty()) {
          r.status = Record::Status::Corrupt;
          r.why = std::move(why);
        }
      }
      if (r.status != Record::Status::Ok) break;
      valid = r.end;
      ++records;
    }
    resumed_ = records;
    if (valid < size) {
      if (r.status == Record::Status::Incomplete) {
        spdlog::warn(
            "{}: incomplete record at byte offset {} ({}) after {} good records; dropping the "
            "last {} bytes (a bake killed mid-write leaves such a record, and so does a corrupt "
            "length field). Resuming from the {} good records",
            name, valid, r.why, records, size - valid, records);
      } else {
        // What follows the bad record: well-formed records (by their
        // checksums; counting stops where the chain breaks).
        std::string dropped;
        if (r.end == 0) {
          dropped =
              "that record and everything after it (with its length unusable, later records "
              "cannot be counted)";
        } else {
          size_t after = 0, pos = r.end;
          while (pos < size) {
            const Record next = readRecord(data, size, pos);
            if (next.status != Record::Status::Ok) break;
            ++after;
            pos = next.end;
          }
          dropped =
              fmt::format("that record and the {} record{} after it", after, after == 1 ? "" : "s");
          if (pos < size)
            dropped += fmt::format(", then {} bytes that do not parse as records", size - pos);
        }
        spdlog::warn(
            "{}: corrupt record at byte offset {} ({}) after {} good records; dropping the {} "
            "bytes from there: {}. Resuming from the {} good records; the dropped cells are "
            "computed again",
            name, valid, r.why, records, size - valid, dropped, records);
      }
    }
  }
  std::error_code ec;
  std::filesystem::resize_file(path_, valid, ec);
  if (ec) throwInputError("{}: cannot truncate journal: {}", name, ec.message());
  if (resumed_ > 0) spdlog::info("resuming bake: {} cells already in {}", resumed_, name);
}

}  // namespace vistream
