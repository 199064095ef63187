// Geometry messages: a batch of faces with their triangles, coded compactly
// (protocol version 2; the schema's Geometry table and protocol/README.md,
// "Geometry encoding", give the byte layout).
//
// What a batch costs: face IDs are sorted and sent as varint deltas;
// materials and triangle counts as runs; vertices are quantized on the
// scene's one QuantizationGrid (sent once, in Welcome), corners shared
// between the batch's faces become one vertex, and the vertices and the
// triangle list are coded either with meshoptimizer's vertex and index codecs
// or as varint deltas (smaller for small batches, whose meshoptimizer streams
// are mostly fixed-size tails, and on some scenes for large ones once
// compressed). zstd then compresses the whole payload when that makes it
// smaller. The encoder tries every combination and sends the smallest; the
// flags in the message say which it picked.
//
// Error bound: a decoded vertex lies within half a grid step of the original
// on every axis (plus the float rounding of the decoded value), so within
// sqrt(3)/2 * step in distance: 0.87 mm on the 1 mm grid every scene up to
// 2 km across gets. Corners outside the grid's box are clamped into it.
// Faces come back sorted by ID (a stable sort: equal IDs keep their order),
// each with its material and its triangles in order and with their winding;
// the index codec may rotate a triangle's corners.
//
// Decoding is safe on untrusted bytes: every count is bounded by the bytes
// that carry it before anything is allocated, the decompressed size is
// bounded before decompressing (a zstd bomb is refused unread), and every
// index is checked. A bad message yields false and an error naming what is
// wrong, never a crash or an out-of-bounds read.
// Thread safety: free functions; the encoder keeps one zstd context per
// thread, nothing else is shared.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "protocol/wire/messages.h"

namespace vistream::wire {

// The scene's one quantization grid: vertex q (three unsigned integers) is at
// origin + q * step (local frame, metres). Sent in Welcome (quant_origin,
// quant_step), so every batch of a session shares it.
struct QuantizationGrid {
  glm::dvec3 origin{0.0};  // local frame, metres
  double step = 1e-3;      // metres, finite and > 0

  // The finest grid a scene's bounds allow: 1 mm, coarser only where the
  // longest side spans more than kMaxGridSteps millimetres (2.1 km).
  static QuantizationGrid forBounds(const Box3f& bounds);

  // The vertex at grid coordinates q, in the local frame.
  glm::vec3 position(const glm::uvec3& q) const { return glm::vec3(origin + glm::dvec3(q) * step); }
};
inline constexpr double kFinestGridStep = 1e-3;      // metres
inline constexpr uint32_t kMaxGridSteps = 1u << 21;  // per axis, over the scene's bounds

struct FaceTriangles {
  uint32_t face = 0;
  uint16_t material = 0;
  std::vector<glm::vec3> corners;  // 3 per triangle (a trailing 1 or 2 are ignored), local frame
  // The prelit colour grids of its triangles (common/light/lighting.h): a
  // level per triangle and their colours one grid after another; both empty
  // when the face has no baked lighting. A batch carries lighting only when
  // every face of it has some.
  std::vector<uint8_t> levels;
  std::vector<glm::u8vec3> colours;
};

// Limits a decoder accepts (far above what a server sends in one message).
inline constexpr uint32_t kMaxGeometryFaces = 1u << 22;
inline constexpr uint32_t kMaxGeometryVertices = 1u << 22;
inline constexpr uint32_t kMaxGeometryIndices = 3u << 22;
inline constexpr uint32_t kMaxGeometryPayloadBytes = 32u << 20;  // after decompression

// Which codings the encoder may pick from (all, by default: it picks the
// smallest message). Tests and benchmarks force one to compare them.
struct GeometryCodings {
  bool meshopt = true;  // at least one of meshopt and varint
  bool varint = true;
  enum class Zstd : uint8_t { WherePays, Never, Always } zstd = Zstd::WherePays;
};

// Encodes a batch (at most 65535 triangles a face are kept; at most
// kMaxGeometryFaces faces and kMaxGeometryVertices distinct corners: the
// caller's contract, checked).
GeometryT encodeGeometry(std::span<const FaceTriangles> faces, const QuantizationGrid& grid,
                         const GeometryCodings& codings = {});

struct DecodedGeometry {
  std::vector<uint32_t> faces;  // ascending
  std::vector<uint16_t> materials;
  std::vector<uint16_t> triangleCounts;
  std::vector<glm::vec3> positions;  // per vertex, local frame
  std::vector<uint32_t> indices;     // 3 per triangle, face by face, each < positions.size()
  // Per triangle its lighting grid's level, and the grids' colours in order;
  // both empty when the message carries no lighting.
  std::vector<uint8_t> levels;
  std::vector<glm::u8vec3> colours;
};
inline constexpr uint64_t kMaxGeometryColours = 1u << 24;  // after decompression, a message

// The lighting section alone (for fuzzing): fills out.levels and out.colours
// for `triangles` triangles.
bool decodeGeometryLighting(std::span<const uint8_t> bytes, size_t triangles, DecodedGeometry& out,
                            std::string& error);

// Decodes a verified Geometry table with the session's grid (from Welcome).
// Returns false and sets `error` on anything inconsistent.
bool decodeGeometry(const Geometry& g, const QuantizationGrid& grid, DecodedGeometry& out,
                    std::string& error);

// The same on the parts of a table: the payload bytes and the two flags
// (for fuzzing the payload without a FlatBuffer around it).
bool decodeGeometryPayload(std::span<const uint8_t> payload, GeometryCodec codec,
                           GeometryCompression compression, const QuantizationGrid& grid,
                           DecodedGeometry& out, std::string& error);

}  // namespace vistream::wire
