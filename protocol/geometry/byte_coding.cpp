#include "protocol/geometry/byte_coding.h"

#include <zstd.h>

#include <memory>

#include "common/core/check.h"

namespace vistream::wire {

namespace {
struct ZstdContextFree {
  void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};
}  // namespace

std::vector<uint8_t> zstdCompress(std::span<const uint8_t> raw, int level) {
  thread_local std::unique_ptr<ZSTD_CCtx, ZstdContextFree> context(ZSTD_createCCtx());
  VS_CHECK(context != nullptr);
  std::vector<uint8_t> out(ZSTD_compressBound(raw.size()));
  const size_t n =
      ZSTD_compressCCtx(context.get(), out.data(), out.size(), raw.data(), raw.size(), level);
  VS_CHECK(!ZSTD_isError(n));  // the bound holds for any input
  out.resize(n);
  return out;
}

std::optional<std::vector<uint8_t>> zstdDecompress(std::span<const uint8_t> frame,
                                                   uint64_t maxBytes, std::string& error) {
  const unsigned long long size = ZSTD_getFrameContentSize(frame.data(), frame.size());
  if (size == ZSTD_CONTENTSIZE_ERROR) {
    error = "not a zstd frame";
    return std::nullopt;
  }
  if (size == ZSTD_CONTENTSIZE_UNKNOWN) {
    error = "a zstd frame that does not state its size";
    return std::nullopt;
  }
  if (size > maxBytes) {
    error = fmt::format("decompresses to {} bytes, more than the limit of {}", size, maxBytes);
    return std::nullopt;
  }
  std::vector<uint8_t> out(static_cast<size_t>(size));
  const size_t n = ZSTD_decompress(out.data(), out.size(), frame.data(), frame.size());
  if (ZSTD_isError(n)) {
    error = fmt::format("does not decompress: {}", ZSTD_getErrorName(n));
    return std::nullopt;
  }
  if (n != out.size()) {
    error = fmt::format("decompresses to {} bytes, its header said {}", n, out.size());
    return std::nullopt;
  }
  return out;
}

}  // namespace vistream::wire
