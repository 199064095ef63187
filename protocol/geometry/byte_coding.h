// Byte-level coding shared by the wire's compact payloads (Geometry,
// impostors): LEB128 varints, zigzag signed values, (run, value) pairs, a
// bounds-checked reader for untrusted payloads whose first failure names the
// field, and zstd frames that state their size, decompressed only within a
// bound given before anything is allocated.
// Thread safety: free functions (zstdCompress keeps one context per thread);
// a PayloadReader belongs to one thread.
#pragma once

#include <fmt/format.h>

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace vistream::wire {

inline void putVarint(std::vector<uint8_t>& out, uint64_t v) {
  while (v >= 0x80) {
    out.push_back(uint8_t(v) | 0x80);
    v >>= 7;
  }
  out.push_back(uint8_t(v));
}

inline uint64_t zigzag(int64_t v) {
  return (uint64_t(v) << 1) ^ uint64_t(v >> 63);
}

// (run length, value) pairs covering `values`.
template <class T>
void putRuns(std::vector<uint8_t>& out, const std::vector<T>& values) {
  for (size_t i = 0; i < values.size();) {
    size_t j = i + 1;
    while (j < values.size() && values[j] == values[i]) ++j;
    putVarint(out, j - i);
    putVarint(out, values[i]);
    i = j;
  }
}

// An ascending (non-decreasing) list of IDs as varint deltas, the first from
// 0 (Geometry's face IDs, the faces an impostor replaces). Read it back with
// readAscending.
inline void putAscending(std::vector<uint8_t>& out, const std::vector<uint32_t>& ids) {
  uint32_t previous = 0;
  for (const uint32_t id : ids) {
    putVarint(out, id - previous);
    previous = id;
  }
}

// An ascending list of distinct IDs as ranges of consecutive IDs: the range
// count, then per range the gap from the previous range's end (the first
// from 0) and the length minus 1, all varints. A building's faces are
// consecutive in a file, so the faces a client holds take a few bytes a
// building. Read it back with readIdRanges.
inline void putIdRanges(std::vector<uint8_t>& out, std::span<const uint32_t> ids) {
  std::vector<std::pair<uint32_t, uint32_t>> ranges;  // first, last
  for (const uint32_t id : ids)
    if (!ranges.empty() && ranges.back().second + 1 == id)
      ranges.back().second = id;
    else
      ranges.emplace_back(id, id);
  putVarint(out, ranges.size());
  uint64_t end = 0;  // one past the previous range
  for (const auto& [first, last] : ranges) {
    putVarint(out, first - end);
    putVarint(out, last - first);
    end = uint64_t(last) + 1;
  }
}

// The bytes a reconnecting client's Hello.held_faces may take: well within
// a server's default inbound frame limit (64 KiB).
inline constexpr size_t kMaxHeldFacesBytes = 48u << 10;

// putIdRanges of the longest prefix of `ids` (halving) that fits `maxBytes`:
// a client names what fits and is sent the rest again.
inline std::vector<uint8_t> idRangesWithin(std::span<const uint32_t> ids, size_t maxBytes) {
  std::vector<uint8_t> out;
  for (size_t n = ids.size();; n /= 2) {
    out.clear();
    putIdRanges(out, ids.first(n));
    if (out.size() <= maxBytes || n == 0) return out;
  }
}

// Reads varints and bytes from a payload; every read is bounds-checked and the
// first failure names the field.
class PayloadReader {
 public:
  explicit PayloadReader(std::span<const uint8_t> bytes) : bytes_(bytes) {}

  // An unsigned varint of at most `max`, or nothing (error set).
  std::optional<uint64_t> varint(const char* field, uint64_t max) {
    uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (at_ >= bytes_.size()) return fail(fmt::format("{} is cut off", field));
      const uint8_t b = bytes_[at_++];
      if (shift == 63 && b > 1) return fail(fmt::format("{} overflows 64 bits", field));
      v |= uint64_t(b & 0x7f) << shift;
      if (!(b & 0x80)) {
        if (v > max) return fail(fmt::format("{} is {}, more than {}", field, v, max));
        return v;
      }
    }
    return fail(fmt::format("{} overflows 64 bits", field));
  }
  std::optional<std::span<const uint8_t>> bytes(const char* field, uint64_t n) {
    if (n > remaining())
      return fail(fmt::format("{} claims {} bytes, {} are left", field, n, remaining()));
    const auto s = bytes_.subspan(at_, size_t(n));
    at_ += size_t(n);
    return s;
  }
  std::span<const uint8_t> rest() {
    const auto s = bytes_.subspan(at_);
    at_ = bytes_.size();
    return s;
  }
  size_t remaining() const { return bytes_.size() - at_; }
  const std::string& error() const { return error_; }
  // Records the first failure.
  std::nullopt_t fail(std::string text) {
    if (error_.empty()) error_ = std::move(text);
    return std::nullopt;
  }

 private:
  std::span<const uint8_t> bytes_;
  size_t at_ = 0;
  std::string error_;
};

// Runs (length, value) covering exactly `count` entries, each value <= max.
template <class T>
bool readRuns(PayloadReader& r, size_t count, uint64_t max, const char* field,
              std::vector<T>& out) {
  out.clear();
  out.reserve(count);
  while (out.size() < count) {
    const auto length = r.varint(field, count - out.size());
    if (!length) return false;
    if (*length == 0) return r.fail(fmt::format("{} has length 0", field)), false;
    const auto value = r.varint(field, max);
    if (!value) return false;
    out.insert(out.end(), size_t(*length), T(*value));
  }
  return true;
}

// `count` IDs written by putAscending, each below `limit`; false (error set)
// if one is cut off or reaches the limit.
inline bool readAscending(PayloadReader& r, size_t count, uint64_t limit, const char* field,
                          std::vector<uint32_t>& out) {
  out.clear();
  out.reserve(count);
  uint64_t id = 0;
  for (size_t i = 0; i < count; ++i) {
    if (limit == 0 || id > limit - 1)
      return r.fail(fmt::format("{} reaches {}", field, limit)), false;
    const auto delta = r.varint(field, limit - 1 - id);
    if (!delta) return false;
    id += *delta;
    out.push_back(uint32_t(id));
  }
  return true;
}

// IDs written by putIdRanges, each below `limit` and at most `maxIds` of
// them; false (error set) if the list is cut off, overlaps itself, reaches
// the limit or holds more.
inline bool readIdRanges(PayloadReader& r, uint64_t limit, size_t maxIds, const char* field,
                         std::vector<uint32_t>& out) {
  out.clear();
  const auto count = r.varint(field, limit);
  if (!count) return false;
  uint64_t end = 0;
  for (uint64_t i = 0; i < *count; ++i) {
    const auto gap = r.varint(field, limit - end);
    if (!gap) return false;
    const uint64_t first = end + *gap;
    if (first >= limit) return r.fail(fmt::format("{} reaches {}", field, limit)), false;
    const auto extra = r.varint(field, limit - 1 - first);
    if (!extra) return false;
    if (out.size() + *extra + 1 > maxIds)
      return r.fail(fmt::format("{} holds more than {} IDs", field, maxIds)), false;
    for (uint64_t id = first; id <= first + *extra; ++id) out.push_back(uint32_t(id));
    end = first + *extra + 1;
  }
  return true;
}

// A zstd frame of `raw` at `level`, its content size in its header.
std::vector<uint8_t> zstdCompress(std::span<const uint8_t> raw, int level = 3);

// The content of a zstd frame that states its size, if that size is at most
// `maxBytes` and the frame holds exactly that; otherwise nothing, with
// `error` naming what is wrong.
std::optional<std::vector<uint8_t>> zstdDecompress(std::span<const uint8_t> frame,
                                                   uint64_t maxBytes, std::string& error);

}  // namespace vistream::wire
