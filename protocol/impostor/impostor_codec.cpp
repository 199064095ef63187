#include "protocol/impostor/impostor_codec.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>

#include "protocol/geometry/byte_coding.h"

namespace vistream::wire {

namespace {

constexpr std::array<uint8_t, 4> kImpostorMagic = {'V', 'I', 'M', 'P'};
constexpr uint8_t kVersion = 1;
constexpr uint8_t kZstdFlag = 1;
constexpr int kImpostorZstdLevel = 6;
constexpr size_t kFloats = 33;

// 16 bits spread to every third bit of 48, and back.
uint64_t spread(uint64_t v) {
  v &= 0xffff;
  v = (v | (v << 16)) & 0x0000ff0000ffULL;
  v = (v | (v << 8)) & 0x00f00f00f00fULL;
  v = (v | (v << 4)) & 0x0c30c30c30c3ULL;
  v = (v | (v << 2)) & 0x249249249249ULL;
  return v;
}
uint64_t compact(uint64_t v) {
  v &= 0x249249249249ULL;
  v = (v | (v >> 2)) & 0x0c30c30c30c3ULL;
  v = (v | (v >> 4)) & 0x00f00f00f00fULL;
  v = (v | (v >> 8)) & 0x0000ff0000ffULL;
  v = (v | (v >> 16)) & 0xffff;
  return v;
}
uint64_t morton(const std::array<uint16_t, 3>& q) {
  return spread(q[0]) | (spread(q[1]) << 1) | (spread(q[2]) << 2);
}

void putFloat(std::vector<uint8_t>& out, float f) {
  uint8_t b[4];
  std::memcpy(b, &f, 4);
  out.insert(out.end(), b, b + 4);
}
void putVec(std::vector<uint8_t>& out, const glm::vec3& v) {
  for (int a = 0; a < 3; ++a) putFloat(out, v[a]);
}

}  // namespace

std::vector<uint8_t> encodeImpostor(const Impostor& imp) {
  std::vector<uint8_t> body;
  putVec(body, imp.cell.lo);
  putVec(body, imp.cell.hi);
  putVec(body, imp.box.lo);
  putVec(body, imp.box.hi);
  putVec(body, imp.plane.origin);
  putVec(body, imp.plane.uAxis);
  putVec(body, imp.plane.vAxis);
  putVec(body, imp.plane.normal);
  for (const glm::vec3& c : imp.cameras) putVec(body, c);
  body.push_back(uint8_t(imp.textureWidth));
  body.push_back(uint8_t(imp.textureHeight));
  const size_t n = imp.size();
  putVarint(body, n);

  // Positions in Morton order of their quantized coordinates.
  const glm::vec3 extent = imp.box.extent();
  std::vector<uint64_t> codes(n);
  for (size_t k = 0; k < n; ++k) {
    std::array<uint16_t, 3> q;
    for (int a = 0; a < 3; ++a) {
      const float f = extent[a] > 0.0f ? (imp.points[k][a] - imp.box.lo[a]) / extent[a] : 0.0f;
      q[size_t(a)] = uint16_t(std::lround(std::clamp(f, 0.0f, 1.0f) * 65535.0f));
    }
    codes[k] = morton(q);
  }
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return codes[a] < codes[b]; });
  uint64_t previous = 0;
  for (uint32_t k : order) {
    putVarint(body, codes[k] - previous);
    previous = codes[k];
  }
  // Single-colour flags.
  for (size_t i = 0; i < n; i += 8) {
    uint8_t bits = 0;
    for (size_t j = i; j < std::min(n, i + 8); ++j)
      bits |= uint8_t((imp.singleColour[order[j]] ? 1 : 0) << (j - i));
    body.push_back(bits);
  }
  // Colours: the first texel, then the others as differences from it.
  const uint32_t texels = imp.textureTexels();
  for (uint32_t k : order) {
    const glm::u8vec3* t = imp.texels.data() + imp.firstTexel[k];
    for (int c = 0; c < 3; ++c) body.push_back(t[0][c]);
    if (imp.singleColour[k]) continue;
    for (uint32_t i = 1; i < texels; ++i)
      for (int c = 0; c < 3; ++c) body.push_back(uint8_t(t[i][c] - t[0][c]));
  }

  std::vector<uint8_t> out(kImpostorMagic.begin(), kImpostorMagic.end());
  out.push_back(kVersion);
  std::vector<uint8_t> z = zstdCompress(body, kImpostorZstdLevel);
  if (z.size() < body.size()) {
    out.push_back(kZstdFlag);
    out.insert(out.end(), z.begin(), z.end());
  } else {
    out.push_back(0);
    out.insert(out.end(), body.begin(), body.end());
  }
  return out;
}

bool decodeImpostor(std::span<const uint8_t> bytes, Impostor& out, std::string& error) {
  auto fail = [&](std::string text) {
    error = "impostor: " + std::move(text);
    return false;
  };
  if (bytes.size() < 6 || !std::equal(kImpostorMagic.begin(), kImpostorMagic.end(), bytes.begin()))
    return fail("does not start with VIMP");
  if (bytes[4] != kVersion) return fail(fmt::format("unknown version {}", unsigned(bytes[4])));
  if (bytes[5] & ~kZstdFlag) return fail(fmt::format("unknown flags {:#x}", unsigned(bytes[5])));
  std::vector<uint8_t> decompressed;
  std::span<const uint8_t> body = bytes.subspan(6);
  if (bytes[5] & kZstdFlag) {
    std::string why;
    auto d = zstdDecompress(body, kMaxImpostorBodyBytes, why);
    if (!d) return fail("the body " + why);
    decompressed = std::move(*d);
    body = decompressed;
  }
  PayloadReader r(body);
  const auto head = r.bytes("the header", kFloats * 4 + 2);
  if (!head) return fail(r.error());
  std::array<float, kFloats> f;
  std::memcpy(f.data(), head->data(), kFloats * 4);
  for (float v : f)
    if (!std::isfinite(v)) return fail("a non-finite number in the header");
  auto vec = [&](size_t i) { return glm::vec3(f[i], f[i + 1], f[i + 2]); };
  Impostor imp;
  imp.cell = Box3f(vec(0), vec(3));
  imp.box = Box3f(vec(6), vec(9));
  if (imp.cell.empty() || imp.box.empty()) return fail("an empty cell or box");
  // A box wider than float can hold (3e38 to -3e38) would turn every point into inf or NaN.
  const glm::vec3 boxExtent = imp.box.extent();
  if (!std::isfinite(boxExtent.x) || !std::isfinite(boxExtent.y) || !std::isfinite(boxExtent.z))
    return fail("a box too large for float coordinates");
  imp.plane.origin = vec(12);
  imp.plane.uAxis = vec(15);
  imp.plane.vAxis = vec(18);
  imp.plane.normal = vec(21);
  for (size_t k = 0; k < 3; ++k) imp.cameras[k] = vec(24 + 3 * k);
  imp.textureWidth = (*head)[kFloats * 4];
  imp.textureHeight = (*head)[kFloats * 4 + 1];
  if (imp.textureWidth < 1 || imp.textureWidth > 64 || imp.textureHeight < 1 ||
      imp.textureHeight > 64)
    return fail(
        fmt::format("texture {}x{} (each side 1 to 64)", imp.textureWidth, imp.textureHeight));
  // Each point takes at least a byte of position and three of colour.
  const auto count =
      r.varint("the point count", std::min<uint64_t>(kMaxImpostorPoints, r.remaining() / 4));
  if (!count) return fail(r.error());
  const size_t n = size_t(*count);
  imp.points.resize(n);
  const glm::vec3 step = imp.box.extent() / 65535.0f;
  uint64_t code = 0;
  for (size_t k = 0; k < n; ++k) {
    const auto delta = r.varint("a position", (uint64_t(1) << 48) - 1 - code);
    if (!delta) return fail(r.error());
    code += *delta;
    const glm::vec3 q(float(compact(code)), float(compact(code >> 1)), float(compact(code >> 2)));
    imp.points[k] = imp.box.lo + q * step;
  }
  const auto flags = r.bytes("the single-colour flags", (n + 7) / 8);
  if (!flags) return fail(r.error());
  imp.singleColour.resize(n);
  imp.firstTexel.resize(n);
  const uint32_t texels = imp.textureTexels();
  size_t total = 0;
  for (size_t k = 0; k < n; ++k) {
    imp.singleColour[k] = ((*flags)[k / 8] >> (k % 8)) & 1;
    imp.firstTexel[k] = uint32_t(total);
    total += imp.singleColour[k] ? 1 : texels;
  }
  const auto colours = r.bytes("the colours", uint64_t(total) * 3);
  if (!colours) return fail(r.error());
  if (r.remaining() != 0) return fail(fmt::format("{} bytes after the colours", r.remaining()));
  imp.texels.resize(total);
  const uint8_t* c = colours->data();
  for (size_t k = 0; k < n; ++k) {
    glm::u8vec3* t = imp.texels.data() + imp.firstTexel[k];
    t[0] = {c[0], c[1], c[2]};
    c += 3;
    if (imp.singleColour[k]) continue;
    for (uint32_t i = 1; i < texels; ++i, c += 3)
      t[i] = {uint8_t(t[0].x + c[0]), uint8_t(t[0].y + c[1]), uint8_t(t[0].z + c[2])};
  }
  imp.boundBlocks();
  out = std::move(imp);
  return true;
}

}  // namespace vistream::wire
