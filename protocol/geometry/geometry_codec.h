// Geometry messages: faces with their triangles, quantized to 16 bits per
// axis over the batch's bounds and compressed with meshoptimizer's vertex and
// index codecs (the schema's Geometry table documents the layout).
//
// Error bound: a decoded vertex lies within half a quantization step of the
// original on every axis, step = (batch extent) / 65535 (3 mm for a 200 m
// batch). Triangles keep their order and winding, but the index codec may
// rotate a triangle's corners. Decoding checks every size and index against the message and
// fails with a message naming the problem; it never reads out of bounds.
// Thread safety: free functions, no shared state.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <string>
#include <vector>

#include "protocol/wire/messages.h"

namespace vistream::wire {

struct FaceTriangles {
  uint32_t face = 0;
  uint16_t material = 0;
  std::vector<glm::vec3> corners;  // 3 per triangle, local frame
};

// Limits a decoder accepts (far above what a server sends in one message).
inline constexpr uint32_t kMaxGeometryVertices = 1u << 22;
inline constexpr uint32_t kMaxGeometryIndices = 3u << 22;

GeometryT encodeGeometry(std::span<const FaceTriangles> faces);

struct DecodedGeometry {
  std::vector<uint32_t> faces;
  std::vector<uint16_t> materials;
  std::vector<uint16_t> triangleCounts;
  std::vector<glm::vec3> positions;  // per vertex
  std::vector<uint32_t> indices;     // 3 per triangle, face by face
};

// Decodes a verified Geometry table. Returns false and sets `error` on any
// inconsistency.
bool decodeGeometry(const Geometry& g, DecodedGeometry& out, std::string& error);

}  // namespace vistream::wire
