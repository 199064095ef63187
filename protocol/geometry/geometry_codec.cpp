// Compact Geometry messages (the layout is in the schema's Geometry table).
// meshoptimizer's documentation recommends its codecs' output be compressed
// further by a general-purpose compressor; zstd does it here, per message,
// where it pays.
#include "protocol/geometry/geometry_codec.h"

#include <fmt/format.h>
#include <meshoptimizer.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>

#include "common/core/check.h"
#include "protocol/geometry/byte_coding.h"

namespace vistream::wire {

namespace {

using GridVertex = std::array<uint32_t, 3>;  // grid coordinates: 12 bytes, meshopt's vertex
static_assert(sizeof(GridVertex) == 12);

// zstd's level for Geometry payloads (a few hundred bytes to tens of KiB).
// Tuned on batches of 30 to 1000 faces of city1 and delfshaven: levels 6 and 9
// saved at most 2% more than 3 for 1.3 to 15 times the time, level 19 3% to
// 7% for 2 to 60 times.
constexpr int kGeometryZstdLevel = 3;

// A lighting grid of level n (common/light/lighting.h, LightingGrid): its
// point count and the index of point (i, j).
constexpr uint32_t pointsOfLevel(uint32_t n) {
  return (n + 1) * (n + 2) / 2;
}
constexpr uint32_t pointIndexOf(uint32_t n, uint32_t i, uint32_t j) {
  return j * (n + 1) - j * (j - 1) / 2 + i;
}
constexpr uint32_t kMaxColourStep = 16;

// ---- the parts of a batch ---------------------------------------------------------

// A batch as integers: what both codings write.
struct IndexedBatch {
  std::vector<uint32_t> order;  // input faces in the order written (sorted by ID)
  std::vector<uint32_t> faces;
  std::vector<uint16_t> materials;
  std::vector<uint16_t> triangleCounts;
  std::vector<GridVertex> vertices;  // in order of first use by `indices`
  std::vector<uint32_t> indices;
};

IndexedBatch indexBatch(std::span<const FaceTriangles> input, const QuantizationGrid& grid) {
  VS_CHECK_LE(input.size(), size_t(kMaxGeometryFaces));
  VS_CHECK(std::isfinite(grid.step) && grid.step > 0.0);
  std::vector<uint32_t> order(input.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return input[a].face < input[b].face; });
  IndexedBatch b;
  b.order = order;
  std::vector<GridVertex> corners;
  const double maxQ = double(std::numeric_limits<uint32_t>::max());
  for (uint32_t i : order) {
    const FaceTriangles& f = input[i];
    const size_t triangles = std::min<size_t>(f.corners.size() / 3, 65535);
    b.faces.push_back(f.face);
    b.materials.push_back(f.material);
    b.triangleCounts.push_back(uint16_t(triangles));
    for (size_t k = 0; k < triangles * 3; ++k) {
      const glm::dvec3 q = glm::round((glm::dvec3(f.corners[k]) - grid.origin) / grid.step);
      GridVertex v;
      for (int a = 0; a < 3; ++a)  // onto the grid (a NaN to 0: no cast of it is defined)
        v[size_t(a)] = q[a] > 0.0 ? uint32_t(std::min(q[a], maxQ)) : 0u;
      corners.push_back(v);
    }
  }
  VS_CHECK_LE(corners.size(), size_t(kMaxGeometryIndices));
  if (corners.empty()) return b;
  // Shared corners become one vertex, numbered in order of first use (what
  // both the index codec and the Varint coding expect).
  std::vector<uint32_t> remap(corners.size());
  const size_t vertexCount = meshopt_generateVertexRemap(
      remap.data(), nullptr, corners.size(), corners.data(), corners.size(), sizeof(GridVertex));
  VS_CHECK_LE(vertexCount, size_t(kMaxGeometryVertices));
  b.vertices.resize(vertexCount);
  meshopt_remapVertexBuffer(b.vertices.data(), corners.data(), corners.size(), sizeof(GridVertex),
                            remap.data());
  b.indices.resize(corners.size());
  meshopt_remapIndexBuffer(b.indices.data(), nullptr, corners.size(), remap.data());
  return b;
}

// Counts, face IDs, materials and triangle counts: the head of every payload.
std::vector<uint8_t> payloadHead(const IndexedBatch& b) {
  std::vector<uint8_t> out;
  putVarint(out, b.faces.size());
  putVarint(out, b.vertices.size());
  putAscending(out, b.faces);
  putRuns(out, b.materials);
  putRuns(out, b.triangleCounts);
  return out;
}

std::vector<uint8_t> meshoptPayload(const IndexedBatch& b, std::vector<uint8_t> out) {
  std::vector<uint8_t> vertices;
  if (!b.vertices.empty()) {
    vertices.resize(meshopt_encodeVertexBufferBound(b.vertices.size(), sizeof(GridVertex)));
    vertices.resize(meshopt_encodeVertexBuffer(vertices.data(), vertices.size(), b.vertices.data(),
                                               b.vertices.size(), sizeof(GridVertex)));
  }
  putVarint(out, vertices.size());
  out.insert(out.end(), vertices.begin(), vertices.end());
  if (!b.indices.empty()) {
    const size_t at = out.size();
    out.resize(at + meshopt_encodeIndexBufferBound(b.indices.size(), b.vertices.size()));
    out.resize(at + meshopt_encodeIndexBuffer(out.data() + at, out.size() - at, b.indices.data(),
                                              b.indices.size()));
  }
  return out;
}

std::vector<uint8_t> varintPayload(const IndexedBatch& b, std::vector<uint8_t> out) {
  GridVertex previous{0, 0, 0};
  for (const GridVertex& v : b.vertices) {
    for (int a = 0; a < 3; ++a) putVarint(out, zigzag(int64_t(v[a]) - int64_t(previous[a])));
    previous = v;
  }
  uint32_t next = 0;  // vertices referenced so far
  for (uint32_t i : b.indices) {
    putVarint(out, next - i);  // first-use order: i <= next
    if (i == next) ++next;
  }
  return out;
}

// ---- lighting -------------------------------------------------------------------------

// The prediction of grid point (i, j) of a level-n grid from the points
// before it (row by row), or of the first point from `previous`.
glm::ivec3 predictPoint(const glm::u8vec3* g, uint32_t n, uint32_t i, uint32_t j,
                        glm::u8vec3 previous) {
  auto at = [&](uint32_t a, uint32_t b) { return glm::ivec3(g[pointIndexOf(n, a, b)]); };
  // Lighting grids carry ray-sampling noise, which a plane through three
  // neighbours would triple; the mean of two halves it.
  if (i > 0 && j > 0) return (at(i - 1, j) + at(i, j - 1) + 1) / 2;
  if (i > 0) return at(i - 1, j);
  if (j > 0) return at(i, j - 1);
  return glm::ivec3(previous);
}

// The lighting section of a batch (layout in the schema), or nothing when
// some face has no lighting.
std::vector<uint8_t> lightingSection(std::span<const FaceTriangles> input, const IndexedBatch& b) {
  for (uint32_t i : b.order) {
    const FaceTriangles& f = input[i];
    const size_t triangles = std::min<size_t>(f.corners.size() / 3, 65535);
    if (f.levels.size() < triangles || f.levels.empty()) return {};
  }
  // The coarsest step whose lattice (multiples of it, and 255) holds every
  // colour: baked colours are posterized (LightingOptions::colourStep), and
  // coding their lattice index instead of the byte shrinks the residuals.
  uint32_t step = kMaxColourStep;
  for (uint32_t i : b.order)
    for (const glm::u8vec3& c : input[i].colours)
      for (int a = 0; a < 3; ++a)
        while (step > 1 && c[a] != 255 && c[a] % step != 0) step /= 2;
  std::vector<uint8_t> raw;
  putVarint(raw, step);
  glm::u8vec3 previous(0);
  std::vector<glm::u8vec3> index;  // a grid's lattice indices
  for (uint32_t i : b.order) {
    const FaceTriangles& f = input[i];
    const size_t triangles = std::min<size_t>(f.corners.size() / 3, 65535);
    size_t at = 0;
    for (size_t t = 0; t < triangles; ++t) {
      const uint32_t n = f.levels[t];
      VS_CHECK(n >= 1);
      VS_CHECK_LE(at + pointsOfLevel(n), f.colours.size());
      putVarint(raw, n);
      index.resize(pointsOfLevel(n));
      for (size_t k = 0; k < index.size(); ++k)
        index[k] = glm::u8vec3((glm::uvec3(f.colours[at + k]) + step / 2) / step);
      const glm::u8vec3* g = index.data();
      for (uint32_t j = 0; j <= n; ++j)
        for (uint32_t k = 0; k + j <= n; ++k) {
          // Green's residual, then red's and blue's minus green's: light
          // scales the three channels together, so those are mostly 0.
          const glm::ivec3 r =
              glm::ivec3(g[pointIndexOf(n, k, j)]) - predictPoint(g, n, k, j, previous);
          raw.push_back(uint8_t(r.g));
          raw.push_back(uint8_t(r.r - r.g));
          raw.push_back(uint8_t(r.b - r.g));
        }
      previous = g[0];
      at += pointsOfLevel(n);
    }
  }
  std::vector<uint8_t> z = zstdCompress(raw, kGeometryZstdLevel);
  std::vector<uint8_t> out;
  out.reserve(1 + std::min(z.size(), raw.size()));
  if (z.size() < raw.size()) {
    out.push_back(1);
    out.insert(out.end(), z.begin(), z.end());
  } else {
    out.push_back(0);
    out.insert(out.end(), raw.begin(), raw.end());
  }
  return out;
}

// ---- decoding ------------------------------------------------------------------------

bool decodeMeshopt(PayloadReader& r, size_t vertexCount, size_t indexCount,
                   std::vector<GridVertex>& vertices, std::vector<uint32_t>& indices,
                   std::string& error) {
  const auto vertexBytes = r.varint("the vertex stream's length", r.remaining());
  const auto stream = vertexBytes ? r.bytes("the vertex stream", *vertexBytes) : std::nullopt;
  if (!stream) return error = r.error(), false;
  const auto indexStream = r.rest();
  // meshoptimizer's streams spend at least 2 bits a byte lane per 16
  // vertices (3 bytes per 16 vertices of 12 bytes) and 1 byte a triangle:
  // counts beyond that are lies, refused before allocating for them.
  if (vertexCount > (stream->size() + 1) * 16 / 3 + 16) {
    error = fmt::format("{} vertices cannot fit in a vertex stream of {} bytes", vertexCount,
                        stream->size());
    return false;
  }
  if (indexCount / 3 > indexStream.size()) {
    error = fmt::format("{} triangles cannot fit in an index stream of {} bytes", indexCount / 3,
                        indexStream.size());
    return false;
  }
  vertices.resize(vertexCount);
  if (vertexCount > 0 &&
      meshopt_decodeVertexBuffer(vertices.data(), vertexCount, sizeof(GridVertex), stream->data(),
                                 stream->size()) != 0) {
    error = "the vertex stream does not decode";
    return false;
  }
  if (vertexCount == 0 && !stream->empty()) {
    error = "a vertex stream for 0 vertices";
    return false;
  }
  indices.resize(indexCount);
  if (indexCount > 0 && meshopt_decodeIndexBuffer(indices.data(), indexCount, sizeof(uint32_t),
                                                  indexStream.data(), indexStream.size()) != 0) {
    error = "the index stream does not decode";
    return false;
  }
  if (indexCount == 0 && !indexStream.empty()) {
    error = fmt::format("{} bytes after the last field", indexStream.size());
    return false;
  }
  return true;
}

bool decodeVarint(PayloadReader& r, size_t vertexCount, size_t indexCount,
                  std::vector<GridVertex>& vertices, std::vector<uint32_t>& indices,
                  std::string& error) {
  // Each vertex takes at least 3 bytes and each index 1: checked before allocating.
  if (vertexCount > r.remaining() / 3 || indexCount > r.remaining() - vertexCount * 3) {
    error = fmt::format("{} vertices and {} indices cannot fit in {} bytes", vertexCount,
                        indexCount, r.remaining());
    return false;
  }
  vertices.resize(vertexCount);
  int64_t previous[3] = {0, 0, 0};
  for (GridVertex& v : vertices)
    for (int a = 0; a < 3; ++a) {
      const auto z = r.varint("a vertex coordinate", std::numeric_limits<uint64_t>::max());
      if (!z) return error = r.error(), false;
      // Un-zigzag; a coordinate must stay a uint32 (|delta| < 2^33 keeps int64 exact).
      if (*z >> 34) return error = "a vertex coordinate's delta is out of range", false;
      const int64_t value = previous[a] + (int64_t(*z >> 1) ^ -int64_t(*z & 1));
      if (value < 0 || value > int64_t(std::numeric_limits<uint32_t>::max()))
        return error = fmt::format("a vertex coordinate {} is off the grid", value), false;
      v[a] = uint32_t(value);
      previous[a] = value;
    }
  indices.resize(indexCount);
  uint64_t next = 0;
  for (uint32_t& i : indices) {
    const auto back = r.varint("an index", next);
    if (!back) return error = r.error(), false;
    i = uint32_t(next - *back);
    if (*back == 0) ++next;
  }
  if (r.remaining() != 0)
    return error = fmt::format("{} bytes after the last field", r.remaining()), false;
  return true;
}

}  // namespace

QuantizationGrid QuantizationGrid::forBounds(const Box3f& bounds) {
  QuantizationGrid g;
  if (bounds.empty()) return g;
  g.origin = glm::dvec3(bounds.lo);
  const glm::dvec3 extent = glm::dvec3(bounds.hi) - glm::dvec3(bounds.lo);
  const double longest = std::max({extent.x, extent.y, extent.z});
  g.step = std::max(kFinestGridStep, longest / double(kMaxGridSteps - 1));
  return g;
}

GeometryT encodeGeometry(std::span<const FaceTriangles> faces, const QuantizationGrid& grid,
                         const GeometryCodings& codings) {
  VS_CHECK(codings.meshopt || codings.varint);
  const IndexedBatch batch = indexBatch(faces, grid);
  const std::vector<uint8_t> head = payloadHead(batch);
  GeometryT best;
  bool picked = false;
  auto offer = [&](GeometryCodec codec, GeometryCompression compression,
                   std::vector<uint8_t> bytes) {
    if (picked && bytes.size() >= best.payload.size()) return;
    picked = true;
    best.codec = codec;
    best.compression = compression;
    best.payload = std::move(bytes);
  };
  auto consider = [&](GeometryCodec codec, std::vector<uint8_t> raw) {
    using Zstd = GeometryCodings::Zstd;
    if (codings.zstd != Zstd::Never) {
      std::vector<uint8_t> z = zstdCompress(raw, kGeometryZstdLevel);
      if (codings.zstd == Zstd::Always || z.size() < raw.size())
        return offer(codec, GeometryCompression::Zstd, std::move(z));
    }
    offer(codec, GeometryCompression::None, std::move(raw));
  };
  if (codings.meshopt) consider(GeometryCodec::Meshopt, meshoptPayload(batch, head));
  // Both codings are cheap (about 1 microsecond a face each, zstd included),
  // and neither always wins: on city1's batches Varint + zstd was the
  // smaller up to 10,000 faces, on delfshaven's Meshopt from 300 faces on.
  if (codings.varint) consider(GeometryCodec::Varint, varintPayload(batch, head));
  best.lighting = lightingSection(faces, batch);
  return best;
}

bool decodeGeometry(const Geometry& g, const QuantizationGrid& grid, DecodedGeometry& out,
                    std::string& error) {
  const auto* payload = g.payload();
  if (!decodeGeometryPayload(payload ? std::span<const uint8_t>(payload->data(), payload->size())
                                     : std::span<const uint8_t>(),
                             g.codec(), g.compression(), grid, out, error))
    return false;
  const auto* lighting = g.lighting();
  if (!lighting || lighting->size() == 0) return true;
  size_t triangles = 0;
  for (uint16_t t : out.triangleCounts) triangles += t;
  if (!decodeGeometryLighting(std::span<const uint8_t>(lighting->data(), lighting->size()),
                              triangles, out, error)) {
    out = {};
    return false;
  }
  return true;
}

bool decodeGeometryLighting(std::span<const uint8_t> bytes, size_t triangles, DecodedGeometry& out,
                            std::string& error) {
  out.levels.clear();
  out.colours.clear();
  auto fail = [&](std::string text) {
    error = "geometry lighting: " + std::move(text);
    out.levels.clear();
    out.colours.clear();
    return false;
  };
  if (bytes.empty()) return fail("no format byte");
  std::vector<uint8_t> decompressed;
  std::span<const uint8_t> raw = bytes.subspan(1);
  if (bytes[0] == 1) {
    const unsigned long long size = ZSTD_getFrameContentSize(raw.data(), raw.size());
    if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN)
      return fail("not a zstd frame stating its size");
    // A level takes at most 2 bytes, a colour 3: beyond that the size is a lie.
    if (size > 3 * kMaxGeometryColours + 2 * uint64_t(triangles))
      return fail(fmt::format("decompresses to {} bytes, more than {} triangles can hold", size,
                              triangles));
    decompressed.resize(size_t(size));
    const size_t n =
        ZSTD_decompress(decompressed.data(), decompressed.size(), raw.data(), raw.size());
    if (ZSTD_isError(n) || n != decompressed.size())
      return fail("does not decompress to the size it states");
    raw = decompressed;
  } else if (bytes[0] != 0) {
    return fail(fmt::format("unknown format {}", unsigned(bytes[0])));
  }
  PayloadReader r(raw);
  const auto step = r.varint("the colour step", kMaxColourStep);
  if (!step) return fail(r.error());
  if (*step == 0 || (*step & (*step - 1)) != 0)
    return fail(fmt::format("a colour step of {}, not a power of 2", *step));
  out.levels.reserve(std::min(triangles, raw.size()));
  glm::u8vec3 previous(0);
  std::vector<glm::u8vec3> index;
  for (size_t t = 0; t < triangles; ++t) {
    const auto n = r.varint("a level", 255);
    if (!n) return fail(r.error());
    if (*n == 0) return fail("a level of 0");
    const uint32_t points = pointsOfLevel(uint32_t(*n));
    if (uint64_t(points) * 3 > r.remaining())
      return fail(fmt::format("a grid of level {} needs {} bytes, {} are left", *n, points * 3,
                              r.remaining()));
    if (out.colours.size() + points > kMaxGeometryColours)
      return fail(fmt::format("more than {} colours", kMaxGeometryColours));
    const auto residuals = r.bytes("a grid", uint64_t(points) * 3);
    index.resize(points);
    glm::u8vec3* g = index.data();
    size_t k = 0;
    for (uint32_t j = 0; j <= *n; ++j)
      for (uint32_t i = 0; i + j <= *n; ++i, ++k) {
        const glm::ivec3 p = predictPoint(g, uint32_t(*n), i, j, previous);
        const uint8_t* e = residuals->data() + 3 * k;
        const int green = int(int8_t(e[0]));
        glm::u8vec3& c = g[pointIndexOf(uint32_t(*n), i, j)];
        c.g = uint8_t(p.g + green);
        c.r = uint8_t(p.r + green + e[1]);
        c.b = uint8_t(p.b + green + e[2]);
      }
    previous = g[0];
    for (const glm::u8vec3& q : index)  // lattice index to colour; 255 tops the lattice
      out.colours.push_back(
          glm::u8vec3(glm::min(glm::uvec3(q) * uint32_t(*step), glm::uvec3(255))));
    out.levels.push_back(uint8_t(*n));
  }
  if (r.remaining() != 0) return fail(fmt::format("{} bytes after the last grid", r.remaining()));
  return true;
}

bool decodeGeometryPayload(std::span<const uint8_t> payload, GeometryCodec codec,
                           GeometryCompression compression, const QuantizationGrid& grid,
                           DecodedGeometry& out, std::string& error) {
  out = {};
  auto fail = [&](std::string text) {
    error = "geometry: " + std::move(text);
    out = {};
    return false;
  };
  if (codec != GeometryCodec::Meshopt && codec != GeometryCodec::Varint)
    return fail(fmt::format("unknown codec {}", unsigned(codec)));
  if (!(std::isfinite(grid.step) && grid.step > 0.0) || !std::isfinite(grid.origin.x) ||
      !std::isfinite(grid.origin.y) || !std::isfinite(grid.origin.z))
    return fail("the quantization grid is not finite and positive");
  std::vector<uint8_t> decompressed;
  switch (compression) {
    case GeometryCompression::None:
      break;
    case GeometryCompression::Zstd: {
      // The size comes from the frame's header and is bounded before anything
      // is allocated; decompression into exactly that many bytes fails if the
      // frame holds more.
      const unsigned long long size = ZSTD_getFrameContentSize(payload.data(), payload.size());
      if (size == ZSTD_CONTENTSIZE_ERROR) return fail("the payload is not a zstd frame");
      if (size == ZSTD_CONTENTSIZE_UNKNOWN)
        return fail("the payload's zstd frame does not state its size");
      if (size > kMaxGeometryPayloadBytes)
        return fail(fmt::format("the payload decompresses to {} bytes, more than the limit of {}",
                                size, kMaxGeometryPayloadBytes));
      decompressed.resize(size_t(size));
      const size_t n =
          ZSTD_decompress(decompressed.data(), decompressed.size(), payload.data(), payload.size());
      if (ZSTD_isError(n))
        return fail(fmt::format("the payload does not decompress: {}", ZSTD_getErrorName(n)));
      if (n != decompressed.size())
        return fail(fmt::format("the payload decompresses to {} bytes, its header said {}", n,
                                decompressed.size()));
      payload = decompressed;
      break;
    }
    default:
      return fail(fmt::format("unknown compression {}", unsigned(compression)));
  }
  if (payload.size() > kMaxGeometryPayloadBytes)
    return fail(fmt::format("a payload of {} bytes, more than the limit of {}", payload.size(),
                            kMaxGeometryPayloadBytes));

  PayloadReader r(payload);
  auto readFailed = [&] { return fail(r.error()); };
  // Every face costs at least a byte (its ID): a count beyond the bytes left is a lie.
  const auto faceCount =
      r.varint("the face count", std::min<uint64_t>(kMaxGeometryFaces, r.remaining()));
  const auto vertexCount =
      faceCount ? r.varint("the vertex count", kMaxGeometryVertices) : std::nullopt;
  if (!vertexCount) return readFailed();
  if (!readAscending(r, size_t(*faceCount), uint64_t(std::numeric_limits<uint32_t>::max()) + 1,
                     "a face ID", out.faces))
    return readFailed();
  if (!readRuns(r, size_t(*faceCount), std::numeric_limits<uint16_t>::max(), "a material run",
                out.materials) ||
      !readRuns(r, size_t(*faceCount), std::numeric_limits<uint16_t>::max(), "a triangle count run",
                out.triangleCounts))
    return readFailed();
  uint64_t triangles = 0;
  for (uint16_t t : out.triangleCounts) triangles += t;
  if (triangles * 3 > kMaxGeometryIndices)
    return fail(
        fmt::format("{} triangles, more than the limit of {}", triangles, kMaxGeometryIndices / 3));
  const size_t indexCount = size_t(triangles * 3);

  std::vector<GridVertex> vertices;
  std::string why;
  const bool decoded =
      codec == GeometryCodec::Meshopt
          ? decodeMeshopt(r, size_t(*vertexCount), indexCount, vertices, out.indices, why)
          : decodeVarint(r, size_t(*vertexCount), indexCount, vertices, out.indices, why);
  if (!decoded) return fail(why);
  for (uint32_t i : out.indices)
    if (i >= vertices.size())
      return fail(fmt::format("index {} past {} vertices", i, vertices.size()));
  out.positions.reserve(vertices.size());
  for (const GridVertex& v : vertices) out.positions.push_back(grid.position({v[0], v[1], v[2]}));
  return true;
}

}  // namespace vistream::wire
