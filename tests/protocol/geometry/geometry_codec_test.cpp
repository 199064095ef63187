#include "protocol/geometry/geometry_codec.h"

#include <gtest/gtest.h>

#include <random>

namespace vistream::wire {
namespace {

// The FlatBuffer of a frame, without its length prefix, in its own (aligned)
// allocation, as FrameDecoder hands it out.
std::vector<uint8_t> frameOf(GeometryT g) {
  const auto frame = encodeMessage(std::move(g));
  return {frame.begin() + kFrameHeaderBytes, frame.end()};
}
std::vector<uint8_t> bufferOf(const flatbuffers::FlatBufferBuilder& b) {
  return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

const Geometry& geometryIn(const std::vector<uint8_t>& buffer) {
  return *GetEnvelope(buffer.data())->payload_as_Geometry();
}

std::vector<FaceTriangles> randomFaces(size_t n, uint32_t seed, float extent) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  std::vector<FaceTriangles> faces;
  for (size_t i = 0; i < n; ++i) {
    FaceTriangles f;
    f.face = uint32_t(i * 3 + 7);
    f.material = uint16_t(i % 5);
    const glm::vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng)),
        d(u(rng), u(rng), u(rng));
    f.corners = {a, b, c, a, c, d};  // a quad: two triangles sharing an edge
    faces.push_back(f);
  }
  return faces;
}

TEST(GeometryCodec, RoundTripsFacesWithinHalfAQuantizationStep) {
  const auto faces = randomFaces(500, 1, 100.0f);
  const auto frame = frameOf(encodeGeometry(faces));
  DecodedGeometry g;
  std::string error;
  ASSERT_TRUE(decodeGeometry(geometryIn(frame), g, error)) << error;
  ASSERT_EQ(g.faces.size(), faces.size());
  const float step = 200.0f / 65535.0f;
  for (size_t i = 0; i < faces.size(); ++i) {
    EXPECT_EQ(g.faces[i], faces[i].face);
    EXPECT_EQ(g.materials[i], faces[i].material);
    ASSERT_EQ(g.triangleCounts[i], 2u);
    for (size_t t = 0; t < 2; ++t) {
      // Corners may come back rotated, winding kept.
      float best = 1e30f;
      for (size_t rot = 0; rot < 3; ++rot) {
        float worst = 0.0f;
        for (size_t k = 0; k < 3; ++k)
          worst = std::max(worst, glm::length(g.positions[g.indices[6 * i + 3 * t + k]] -
                                              faces[i].corners[3 * t + (k + rot) % 3]));
        best = std::min(best, worst);
      }
      EXPECT_LE(best, 0.87f * step + 1e-4f);
    }
  }
  // Shared corners are shared vertices, and the codecs compress.
  EXPECT_LT(g.positions.size(), 6 * faces.size());
  EXPECT_LT(frame.size(), faces.size() * 6 * 12);
}

TEST(GeometryCodec, AnEmptyBatchRoundTrips) {
  const auto frame = frameOf(encodeGeometry({}));
  DecodedGeometry g;
  std::string error;
  ASSERT_TRUE(decodeGeometry(geometryIn(frame), g, error)) << error;
  EXPECT_TRUE(g.faces.empty());
}

TEST(GeometryCodec, AMessageWithNoFieldsAtAllDecodesAsEmpty) {
  flatbuffers::FlatBufferBuilder b;
  GeometryBuilder gb(b);
  const auto geometry = gb.Finish();
  b.Finish(CreateEnvelope(b, Payload::Geometry, geometry.Union()));
  const auto frame = bufferOf(b);
  DecodedGeometry g;
  std::string error;
  // No quantization: rejected, without reading any absent vector.
  EXPECT_FALSE(decodeGeometry(geometryIn(frame), g, error));
  EXPECT_FALSE(error.empty());
}

TEST(GeometryCodec, RejectsInconsistentMessagesWithAMessage) {
  auto base = encodeGeometry(randomFaces(10, 2, 5.0f));
  auto expectRejected = [](GeometryT g, const char* what) {
    const auto frame = frameOf(std::move(g));
    DecodedGeometry out;
    std::string error;
    EXPECT_FALSE(decodeGeometry(geometryIn(frame), out, error)) << what;
    EXPECT_FALSE(error.empty()) << what;
  };
  {
    GeometryT g = base;
    g.face_materials.pop_back();
    expectRejected(std::move(g), "lengths differ");
  }
  {
    GeometryT g = base;
    g.index_count += 3;
    expectRejected(std::move(g), "index count");
  }
  {
    GeometryT g = base;
    g.vertex_count = kMaxGeometryVertices + 1;
    expectRejected(std::move(g), "too many vertices");
  }
  {
    GeometryT g = base;
    g.vertices.resize(g.vertices.size() / 2);
    expectRejected(std::move(g), "truncated vertices");
  }
  {
    GeometryT g = base;
    for (auto& b : g.indices) b = 0xff;
    expectRejected(std::move(g), "garbage indices");
  }
  {
    GeometryT g = base;
    g.quant_step = std::make_unique<Vec3f>(std::numeric_limits<float>::infinity(), 1.0f, 1.0f);
    expectRejected(std::move(g), "non-finite step");
  }
}

}  // namespace
}  // namespace vistream::wire
