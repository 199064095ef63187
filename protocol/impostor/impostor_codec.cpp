#include "protocol/impostor/impostor_codec.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>
#include <optional>

#include "common/core/check.h"
#include "protocol/geometry/byte_coding.h"

namespace vistream::wire {

namespace {

constexpr std::array<uint8_t, 4> kImpostorMagic = {'V', 'I', 'M', 'P'};
constexpr uint8_t kVersion = 2;
constexpr int kImpostorZstdLevel = 19;
constexpr size_t kFloats = 33;
constexpr size_t kSections = 4;
constexpr float kNearSlacks = 4.0f;
constexpr std::array<const char*, kSections> kSectionNames = {
    "the positions", "the single-colour flags", "the single colours", "the textures"};

// 21 bits spread to every third bit of 63, and back.
uint64_t spread(uint64_t v) {
  v &= 0x1fffff;
  v = (v | (v << 32)) & 0x1f00000000ffffULL;
  v = (v | (v << 16)) & 0x1f0000ff0000ffULL;
  v = (v | (v << 8)) & 0x100f00f00f00f00fULL;
  v = (v | (v << 4)) & 0x10c30c30c30c30c3ULL;
  v = (v | (v << 2)) & 0x1249249249249249ULL;
  return v;
}
uint64_t compact(uint64_t v) {
  v &= 0x1249249249249249ULL;
  v = (v | (v >> 2)) & 0x10c30c30c30c30c3ULL;
  v = (v | (v >> 4)) & 0x100f00f00f00f00fULL;
  v = (v | (v >> 8)) & 0x1f0000ff0000ffULL;
  v = (v | (v >> 16)) & 0x1f00000000ffffULL;
  v = (v | (v >> 32)) & 0x1fffff;
  return v;
}
uint64_t morton(const std::array<uint32_t, 3>& q) {
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

// A section: its length, a mode byte (0 raw, 1 zstd) and its bytes.
void putSection(std::vector<uint8_t>& out, const std::vector<uint8_t>& raw) {
  std::vector<uint8_t> z =
      raw.empty() ? std::vector<uint8_t>{} : zstdCompress(raw, kImpostorZstdLevel);
  const bool packed = !raw.empty() && z.size() < raw.size();
  const std::vector<uint8_t>& stored = packed ? z : raw;
  putVarint(out, stored.size());
  out.push_back(packed ? 1 : 0);
  out.insert(out.end(), stored.begin(), stored.end());
}

// The texel a texel is predicted from: the one to its left, or above it at
// the start of a row (the first texel is predicted from the previous point's).
uint32_t predictorOf(uint32_t i, uint32_t width) {
  return i % width == 0 ? i - width : i - 1;
}

}  // namespace

std::vector<uint8_t> encodeImpostor(const Impostor& imp, ImpostorSections* sizes) {
  std::vector<uint8_t> out(kImpostorMagic.begin(), kImpostorMagic.end());
  out.push_back(kVersion);
  out.push_back(0);  // flags: none defined
  putVec(out, imp.cell.lo);
  putVec(out, imp.cell.hi);
  putVec(out, imp.box.lo);
  putVec(out, imp.box.hi);
  putVec(out, imp.plane.origin);
  putVec(out, imp.plane.uAxis);
  putVec(out, imp.plane.vAxis);
  putVec(out, imp.plane.normal);
  for (const glm::vec3& c : imp.cameras) putVec(out, c);
  putFloat(out, imp.angleStep);
  putFloat(out, imp.logDepthStep);
  out.push_back(uint8_t(imp.colourStep));
  out.push_back(uint8_t(imp.textureWidth));
  out.push_back(uint8_t(imp.textureHeight));
  const size_t n = imp.size();
  putVarint(out, n);
  const size_t headerBytes = out.size();

  // Positions in Morton order of their grid coordinates, as varint deltas.
  const std::optional<PointGrid> grid = imp.pointGrid();
  VS_CHECK(grid.has_value());  // the contract: the box lies in front of the cell
  std::vector<uint64_t> codes(n);
  for (size_t k = 0; k < n; ++k) codes[k] = morton(grid->coordinates(imp.points[k]));
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return codes[a] < codes[b]; });
  std::array<std::vector<uint8_t>, kSections> raw;
  uint64_t previous = 0;
  for (uint32_t k : order) {
    putVarint(raw[0], codes[k] - previous);
    previous = codes[k];
  }
  // Single-colour flags, a bit a point (LSB first).
  raw[1].assign((n + 7) / 8, 0);
  for (size_t j = 0; j < n; ++j)
    raw[1][j / 8] |= uint8_t((imp.singleColour[order[j]] ? 1 : 0) << (j % 8));
  // Colours, channel by channel: each single-colour point's colour as the
  // difference from the previous single-colour point's (Morton neighbours
  // share a surface); each textured point's texels as multiples of the
  // colour step, its first as the difference from the previous textured
  // point's first, the others from the texel before them.
  const uint32_t step = std::max<uint32_t>(1, imp.colourStep);
  const uint32_t texels = imp.textureTexels();
  for (int c = 0; c < 3; ++c) {
    uint8_t lastSingle = 0, lastFirst = 0;
    for (uint32_t k : order) {
      const glm::u8vec3* t = imp.texels.data() + imp.firstTexel[k];
      if (imp.singleColour[k]) {
        raw[2].push_back(uint8_t(t[0][c] - lastSingle));
        lastSingle = t[0][c];
        continue;
      }
      for (uint32_t i = 0; i < texels; ++i) {
        const uint8_t v = Impostor::levelIndex(t[i][c], step);
        const uint8_t predicted =
            i == 0 ? lastFirst : Impostor::levelIndex(t[predictorOf(i, imp.textureWidth)][c], step);
        raw[3].push_back(uint8_t(v - predicted));
        if (i == 0) lastFirst = v;
      }
    }
  }
  for (size_t i = 0; i < kSections; ++i) {
    const size_t before = out.size();
    putSection(out, raw[i]);
    if (sizes) sizes->bytes[i] = out.size() - before;
  }
  if (sizes) sizes->header = headerBytes;
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
  if (bytes[5] != 0) return fail(fmt::format("unknown flags {:#x}", unsigned(bytes[5])));
  PayloadReader r(bytes.subspan(6));
  const auto head = r.bytes("the header", (kFloats + 2) * 4 + 3);
  if (!head) return fail(r.error());
  std::array<float, kFloats + 2> f;
  std::memcpy(f.data(), head->data(), (kFloats + 2) * 4);
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
  imp.angleStep = f[kFloats];
  imp.logDepthStep = f[kFloats + 1];
  if (imp.angleStep < 0.0f || imp.logDepthStep < 0.0f)
    return fail(fmt::format("grid steps {} and {}", imp.angleStep, imp.logDepthStep));
  const std::optional<PointGrid> grid = imp.pointGrid();
  if (!grid)
    return fail("a box not wholly in front of the cell, or a degenerate sampling plane or grid");
  const uint8_t* tail = head->data() + (kFloats + 2) * 4;
  imp.colourStep = tail[0];
  if (!Impostor::isColourStep(imp.colourStep))
    return fail(fmt::format("colour step {} (1, 2, 4, 8 or 16)", imp.colourStep));
  imp.textureWidth = tail[1];
  imp.textureHeight = tail[2];
  if (imp.textureWidth < 1 || imp.textureWidth > 64 || imp.textureHeight < 1 ||
      imp.textureHeight > 64)
    return fail(
        fmt::format("texture {}x{} (each side 1 to 64)", imp.textureWidth, imp.textureHeight));
  const auto count = r.varint("the point count", kMaxImpostorPoints);
  if (!count) return fail(r.error());
  const size_t n = size_t(*count);

  // The sections, each within the most its content can take.
  std::array<std::vector<uint8_t>, kSections> sections;
  auto section = [&](size_t i, uint64_t maxBytes) {
    const auto stored = r.varint(kSectionNames[i], kMaxImpostorBodyBytes);
    if (!stored) return fail(r.error());
    const auto mode = r.bytes(kSectionNames[i], 1);
    if (!mode) return fail(r.error());
    const auto payload = r.bytes(kSectionNames[i], *stored);
    if (!payload) return fail(r.error());
    if ((*mode)[0] == 0) {
      if (payload->size() > maxBytes)
        return fail(fmt::format("{} take {} bytes, more than {}", kSectionNames[i], payload->size(),
                                maxBytes));
      sections[i].assign(payload->begin(), payload->end());
      return true;
    }
    if ((*mode)[0] != 1)
      return fail(fmt::format("{} have mode {}", kSectionNames[i], unsigned((*mode)[0])));
    std::string why;
    auto d = zstdDecompress(*payload, maxBytes, why);
    if (!d) return fail(fmt::format("{}: {}", kSectionNames[i], why));
    sections[i] = std::move(*d);
    return true;
  };
  const uint32_t texels = imp.textureTexels();
  if (!section(0, uint64_t(n) * 10) || !section(1, (n + 7) / 8) || !section(2, uint64_t(n) * 3) ||
      !section(3, uint64_t(n) * 3 * texels))
    return false;
  if (r.remaining() != 0) return fail(fmt::format("{} bytes after the textures", r.remaining()));

  // Positions: each takes at least a byte.
  if (sections[0].size() < n)
    return fail(fmt::format("{} points in {} bytes of positions", n, sections[0].size()));
  imp.points.resize(n);
  {
    PayloadReader p(sections[0]);
    // A grid point stands within the slack of its box; re-quantizing a
    // decoded point can move it by float rounding a little past that, so a
    // point within kNearSlacks slacks is pulled back to the slack and one
    // farther out is refused.
    const Box3f kept(imp.box.lo - grid->slack, imp.box.hi + grid->slack);
    const Box3f near(imp.box.lo - kNearSlacks * grid->slack,
                     imp.box.hi + kNearSlacks * grid->slack);
    uint64_t code = 0;
    for (size_t k = 0; k < n; ++k) {
      const auto delta = p.varint("a position", (uint64_t(1) << 63) - 1 - code);
      if (!delta) return fail(p.error());
      code += *delta;
      const std::array<uint32_t, 3> q = {uint32_t(compact(code)), uint32_t(compact(code >> 1)),
                                         uint32_t(compact(code >> 2))};
      for (size_t a = 0; a < 3; ++a)
        if (q[a] > grid->steps[a]) return fail("a position outside the grid");
      const glm::vec3 p3 = grid->point(q);
      if (!std::isfinite(p3.x) || !std::isfinite(p3.y) || !std::isfinite(p3.z) ||
          !near.contains(p3))
        return fail("a position outside the box");
      imp.points[k] = glm::clamp(p3, kept.lo, kept.hi);
    }
    if (p.remaining() != 0) return fail(fmt::format("{} bytes after the positions", p.remaining()));
  }
  // Flags.
  if (sections[1].size() != (n + 7) / 8)
    return fail(fmt::format("the single-colour flags take {} bytes, not {}", sections[1].size(),
                            (n + 7) / 8));
  imp.singleColour.resize(n);
  imp.firstTexel.resize(n);
  size_t total = 0, textured = 0;
  for (size_t k = 0; k < n; ++k) {
    imp.singleColour[k] = (sections[1][k / 8] >> (k % 8)) & 1;
    imp.firstTexel[k] = uint32_t(total);
    total += imp.singleColour[k] ? 1 : texels;
    textured += imp.singleColour[k] ? 0 : 1;
  }
  if (sections[2].size() != (n - textured) * 3)
    return fail(fmt::format("the single colours take {} bytes, not {}", sections[2].size(),
                            (n - textured) * 3));
  if (sections[3].size() != textured * texels * 3)
    return fail(fmt::format("the textures take {} bytes, not {}", sections[3].size(),
                            textured * texels * 3));
  // Colours.
  const uint32_t step = imp.colourStep;
  const uint32_t maxIndex = (255 + step / 2) / step;
  imp.texels.resize(total);
  const uint8_t* single = sections[2].data();
  const uint8_t* texture = sections[3].data();
  for (int c = 0; c < 3; ++c) {
    uint8_t lastSingle = 0, lastFirst = 0;
    for (size_t k = 0; k < n; ++k) {
      glm::u8vec3* t = imp.texels.data() + imp.firstTexel[k];
      if (imp.singleColour[k]) {
        lastSingle = uint8_t(lastSingle + *single++);
        t[0][c] = lastSingle;
        continue;
      }
      for (uint32_t i = 0; i < texels; ++i) {
        const uint8_t predicted =
            i == 0 ? lastFirst : Impostor::levelIndex(t[predictorOf(i, imp.textureWidth)][c], step);
        const uint8_t v = uint8_t(predicted + *texture++);
        if (v > maxIndex) return fail("a texel beyond 255");
        t[i][c] = Impostor::levelOf(v, step);
        if (i == 0) lastFirst = v;
      }
    }
  }
  imp.boundBlocks();
  out = std::move(imp);
  return true;
}

}  // namespace vistream::wire
