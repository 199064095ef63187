#include "protocol/geometry/geometry_codec.h"

#include <fmt/format.h>
#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace vistream::wire {

namespace {
using QuantizedVertex = std::array<uint16_t, 4>;  // x, y, z, 0: 8 bytes
}  // namespace

GeometryT encodeGeometry(std::span<const FaceTriangles> faces) {
  GeometryT g;
  glm::dvec3 lo(std::numeric_limits<double>::infinity()),
      hi(-std::numeric_limits<double>::infinity());
  size_t corners = 0;
  for (const FaceTriangles& f : faces) {
    for (const glm::vec3& c : f.corners) {
      lo = glm::min(lo, glm::dvec3(c));
      hi = glm::max(hi, glm::dvec3(c));
    }
    corners += f.corners.size() / 3 * 3;
  }
  if (corners == 0) lo = hi = glm::dvec3(0.0);
  const glm::dvec3 step = glm::max((hi - lo) / 65535.0, glm::dvec3(1e-9));
  g.quant_origin = std::make_unique<Vec3d>(toWire(lo));
  g.quant_step = std::make_unique<Vec3f>(toWire(glm::vec3(step)));
  const glm::dvec3 fstep = glm::dvec3(glm::vec3(step));  // what the decoder multiplies by

  std::vector<QuantizedVertex> unindexed;
  unindexed.reserve(corners);
  for (const FaceTriangles& f : faces) {
    const size_t n = f.corners.size() / 3 * 3;
    g.face_ids.push_back(f.face);
    g.face_materials.push_back(f.material);
    g.face_triangle_counts.push_back(uint16_t(std::min<size_t>(n / 3, 65535)));
    for (size_t i = 0; i < size_t(g.face_triangle_counts.back()) * 3; ++i) {
      const glm::dvec3 q = glm::round((glm::dvec3(f.corners[i]) - lo) / fstep);
      const glm::dvec3 c = glm::clamp(q, glm::dvec3(0.0), glm::dvec3(65535.0));
      unindexed.push_back({uint16_t(c.x), uint16_t(c.y), uint16_t(c.z), 0});
    }
  }
  // Shared corners become one vertex; then the codecs.
  std::vector<uint32_t> remap(unindexed.size());
  const size_t vertexCount =
      unindexed.empty()
          ? 0
          : meshopt_generateVertexRemap(remap.data(), nullptr, unindexed.size(), unindexed.data(),
                                        unindexed.size(), sizeof(QuantizedVertex));
  std::vector<QuantizedVertex> vertices(vertexCount);
  std::vector<uint32_t> indices(unindexed.size());
  if (!unindexed.empty()) {
    meshopt_remapVertexBuffer(vertices.data(), unindexed.data(), unindexed.size(),
                              sizeof(QuantizedVertex), remap.data());
    meshopt_remapIndexBuffer(indices.data(), nullptr, unindexed.size(), remap.data());
  }
  g.vertex_count = uint32_t(vertexCount);
  g.index_count = uint32_t(indices.size());
  if (vertexCount > 0) {
    g.vertices.resize(meshopt_encodeVertexBufferBound(vertexCount, sizeof(QuantizedVertex)));
    g.vertices.resize(meshopt_encodeVertexBuffer(g.vertices.data(), g.vertices.size(),
                                                 vertices.data(), vertexCount,
                                                 sizeof(QuantizedVertex)));
    g.indices.resize(meshopt_encodeIndexBufferBound(indices.size(), vertexCount));
    g.indices.resize(meshopt_encodeIndexBuffer(g.indices.data(), g.indices.size(), indices.data(),
                                               indices.size()));
  }
  g.codec = GeometryCodec::Meshopt;
  return g;
}

bool decodeGeometry(const Geometry& g, DecodedGeometry& out, std::string& error) {
  out = {};
  if (g.codec() != GeometryCodec::Meshopt) {
    error = fmt::format("unknown geometry codec {}", int(g.codec()));
    return false;
  }
  const size_t nf = g.face_ids() ? g.face_ids()->size() : 0;
  if ((g.face_materials() ? g.face_materials()->size() : 0) != nf ||
      (g.face_triangle_counts() ? g.face_triangle_counts()->size() : 0) != nf) {
    error = "geometry: face_ids, face_materials and face_triangle_counts differ in length";
    return false;
  }
  uint64_t triangles = 0;
  for (size_t i = 0; i < nf; ++i) triangles += g.face_triangle_counts()->Get(uint32_t(i));
  if (g.vertex_count() > kMaxGeometryVertices || g.index_count() > kMaxGeometryIndices ||
      triangles * 3 != g.index_count()) {
    error = fmt::format("geometry: {} vertices, {} indices for {} triangles", g.vertex_count(),
                        g.index_count(), triangles);
    return false;
  }
  if (!isFinite(g.quant_origin()) || !isFinite(g.quant_step())) {
    error = "geometry: missing or non-finite quantization";
    return false;
  }
  std::vector<QuantizedVertex> vertices(g.vertex_count());
  const auto* vb = g.vertices();
  const auto* ib = g.indices();
  if (g.vertex_count() > 0 &&
      (!vb || meshopt_decodeVertexBuffer(vertices.data(), vertices.size(), sizeof(QuantizedVertex),
                                         vb->data(), vb->size()) != 0)) {
    error = "geometry: vertex data does not decode";
    return false;
  }
  out.indices.resize(g.index_count());
  if (g.index_count() > 0 &&
      (!ib || meshopt_decodeIndexBuffer(out.indices.data(), out.indices.size(), ib->data(),
                                        ib->size()) != 0)) {
    error = "geometry: index data does not decode";
    return false;
  }
  for (uint32_t i : out.indices)
    if (i >= g.vertex_count()) {
      error = fmt::format("geometry: index {} past {} vertices", i, g.vertex_count());
      return false;
    }
  const glm::dvec3 origin = fromWire(*g.quant_origin());
  const glm::dvec3 step(fromWire(*g.quant_step()));
  out.positions.reserve(vertices.size());
  for (const QuantizedVertex& v : vertices)
    out.positions.push_back(glm::vec3(origin + glm::dvec3(v[0], v[1], v[2]) * step));
  if (nf > 0) {  // absent vectors are empty
    out.faces.assign(g.face_ids()->begin(), g.face_ids()->end());
    out.materials.assign(g.face_materials()->begin(), g.face_materials()->end());
    out.triangleCounts.assign(g.face_triangle_counts()->begin(), g.face_triangle_counts()->end());
  }
  return true;
}

}  // namespace vistream::wire
