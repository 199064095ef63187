#include "protocol/geometry/geometry_codec.h"

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>

#include "common/generate/scene_spec.h"

namespace vistream::wire {
namespace {

// ---- helpers --------------------------------------------------------------------

// The FlatBuffer of a frame, without its length prefix, in its own (aligned)
// allocation, as FrameDecoder hands it out.
std::vector<uint8_t> frameOf(GeometryT g) {
  const auto frame = encodeMessage(std::move(g));
  return {frame.begin() + kFrameHeaderBytes, frame.end()};
}
const Geometry& geometryIn(const std::vector<uint8_t>& buffer) {
  return *GetEnvelope(buffer.data())->payload_as_Geometry();
}

// Encodes, frames and decodes; fails the test if decoding fails.
DecodedGeometry roundTrip(std::span<const FaceTriangles> faces, const QuantizationGrid& grid,
                          const GeometryCodings& codings = {}) {
  const auto frame = frameOf(encodeGeometry(faces, grid, codings));
  DecodedGeometry g;
  std::string error;
  EXPECT_TRUE(decodeGeometry(geometryIn(frame), grid, g, error)) << error;
  return g;
}

// The oracle: the input sorted by ID (equal IDs in input order), each face
// with its material and its triangles (a trailing 1 or 2 corners dropped);
// each decoded corner within half a grid step of the input's on every axis
// (plus the float rounding of a coordinate of this size), a triangle's
// corners possibly rotated but never reflected.
void expectDecodesTo(std::span<const FaceTriangles> input, const DecodedGeometry& g,
                     const QuantizationGrid& grid) {
  std::vector<const FaceTriangles*> expected;
  for (const FaceTriangles& f : input) expected.push_back(&f);
  std::stable_sort(
      expected.begin(), expected.end(),
      [](const FaceTriangles* a, const FaceTriangles* b) { return a->face < b->face; });
  ASSERT_EQ(g.faces.size(), expected.size());
  ASSERT_EQ(g.materials.size(), expected.size());
  ASSERT_EQ(g.triangleCounts.size(), expected.size());
  size_t triangles = 0;
  for (uint16_t t : g.triangleCounts) triangles += t;
  ASSERT_EQ(g.indices.size(), 3 * triangles);
  for (uint32_t i : g.indices) ASSERT_LT(i, g.positions.size());
  auto close = [&](const glm::vec3& decoded, const glm::vec3& original) {
    for (int a = 0; a < 3; ++a) {
      const double slack = 0.5 * grid.step + 4.0 * std::numeric_limits<float>::epsilon() *
                                                 (std::abs(double(original[a])) + 1.0);
      if (std::abs(double(decoded[a]) - double(original[a])) > slack) return false;
    }
    return true;
  };
  size_t at = 0;  // first index of the face's triangles
  for (size_t i = 0; i < expected.size(); ++i) {
    const FaceTriangles& f = *expected[i];
    SCOPED_TRACE(fmt::format("face {} (#{} in ID order)", f.face, i));
    EXPECT_EQ(g.faces[i], f.face);
    EXPECT_EQ(g.materials[i], f.material);
    ASSERT_EQ(g.triangleCounts[i], f.corners.size() / 3);
    for (size_t t = 0; t < g.triangleCounts[i]; ++t, at += 3) {
      bool matched = false;
      for (size_t rot = 0; rot < 3 && !matched; ++rot) {
        matched = true;
        for (size_t k = 0; k < 3; ++k)
          matched =
              matched && close(g.positions[g.indices[at + k]], f.corners[3 * t + (k + rot) % 3]);
      }
      EXPECT_TRUE(matched) << "triangle " << t;
    }
  }
}

// A random batch: unique IDs (sparse, with dense runs) in random order,
// materials in runs and at random, 0 to 4 triangles a face, corners drawn
// from a small pool (so faces share them) or anywhere in `box`.
std::vector<FaceTriangles> randomBatch(size_t n, uint32_t seed, const Box3f& box,
                                       bool duplicateIds = false) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> x(box.lo.x, box.hi.x), y(box.lo.y, box.hi.y),
      z(box.lo.z, box.hi.z);
  std::vector<glm::vec3> pool(std::max<size_t>(4, n));
  for (glm::vec3& p : pool) p = {x(rng), y(rng), z(rng)};
  std::vector<FaceTriangles> faces;
  uint32_t id = std::uniform_int_distribution<uint32_t>(0, 1u << 30)(rng);
  uint16_t material = 0;
  for (size_t i = 0; i < n; ++i) {
    FaceTriangles f;
    id += rng() % 3 == 0 ? 1 + rng() % 100000 : 1;
    f.face = id;
    if (rng() % 4 == 0) material = uint16_t(rng() % 3 == 0 ? rng() : rng() % 8);
    f.material = material;
    const size_t triangles = rng() % 5;
    for (size_t k = 0; k < 3 * triangles; ++k)
      f.corners.push_back(rng() % 2 ? pool[rng() % pool.size()]
                                    : glm::vec3(x(rng), y(rng), z(rng)));
    if (rng() % 10 == 0) f.corners.push_back(pool[0]);  // a stray corner, ignored
    faces.push_back(std::move(f));
  }
  if (duplicateIds && n > 2) faces[n - 1].face = faces[n / 2].face;
  std::shuffle(faces.begin(), faces.end(), rng);
  return faces;
}

// Each face of a scene as the server streams it (StreamWorld's FaceTriangles).
std::vector<FaceTriangles> facesOf(const Scene& scene) {
  std::vector<FaceTriangles> faces(scene.faceCount);
  for (uint32_t i = 0; i < scene.faceCount; ++i) faces[i].face = i;
  for (const Object& o : scene.objects)
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      FaceTriangles& f = faces.at(o.mesh.faceIds[t]);
      f.material = uint16_t(t < o.mesh.materials.size() ? o.mesh.materials[t] : 0);
      for (int k = 0; k < 3; ++k) f.corners.push_back(o.mesh.positions[o.mesh.triangles[t][k]]);
    }
  return faces;
}

// Batches as the server makes them: the n faces nearest to a point (a view
// cell's new faces are a neighbourhood), in the scene's ID order.
std::vector<FaceTriangles> nearestFaces(const std::vector<FaceTriangles>& faces, size_t n,
                                        const glm::vec3& centre) {
  std::vector<std::pair<float, uint32_t>> byDistance;
  for (const FaceTriangles& f : faces)
    if (!f.corners.empty()) byDistance.push_back({glm::distance(f.corners[0], centre), f.face});
  n = std::min(n, byDistance.size());
  std::partial_sort(byDistance.begin(), byDistance.begin() + ptrdiff_t(n), byDistance.end());
  std::vector<FaceTriangles> batch;
  for (size_t i = 0; i < n; ++i) batch.push_back(faces[byDistance[i].second]);
  return batch;
}

struct RealScene {
  std::string name;
  Scene scene;
  std::vector<FaceTriangles> faces;
  QuantizationGrid grid;
};
const std::vector<RealScene>& realScenes() {
  static const std::vector<RealScene> scenes = [] {
    std::vector<RealScene> s;
    for (const std::string& spec :
         {std::string("city1"), std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj"}) {
      RealScene r{spec.substr(spec.find_last_of('/') + 1), openScene(spec), {}, {}};
      r.faces = facesOf(r.scene);
      r.grid = QuantizationGrid::forBounds(r.scene.bounds());
      s.push_back(std::move(r));
    }
    return s;
  }();
  return scenes;
}

// Batch centres: points of the scene's bounds, the same for every run.
std::vector<glm::vec3> centresIn(const Box3f& b, size_t n) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<glm::vec3> c;
  for (size_t i = 0; i < n; ++i)
    c.push_back(b.lo + (b.hi - b.lo) * glm::vec3(u(rng), 0.0f, u(rng)));
  return c;
}

// The four forced codings and the free choice.
struct NamedCodings {
  const char* name;
  GeometryCodings codings;
};
std::vector<NamedCodings> everyCoding() {
  using Zstd = GeometryCodings::Zstd;
  return {{"meshopt", {true, false, Zstd::Never}},
          {"meshopt+zstd", {true, false, Zstd::Always}},
          {"varint", {false, true, Zstd::Never}},
          {"varint+zstd", {false, true, Zstd::Always}},
          {"chosen", {}}};
}

// ---- the grid ---------------------------------------------------------------------

TEST(QuantizationGrid, IsOneMillimetreUpTo2KmAndCoversTheBoundsBeyond) {
  const QuantizationGrid small =
      QuantizationGrid::forBounds(Box3f({-300, 0, -200}, {300, 80, 200}));
  EXPECT_EQ(small.origin, glm::dvec3(-300, 0, -200));
  EXPECT_EQ(small.step, 1e-3);
  const QuantizationGrid big = QuantizationGrid::forBounds(Box3f({0, 0, 0}, {10000, 50, 4000}));
  EXPECT_GT(big.step, 1e-3);
  EXPECT_LE(10000.0 / big.step, double(kMaxGridSteps));
  EXPECT_GE(10000.0 / big.step, double(kMaxGridSteps) - 2.0);
  EXPECT_EQ(QuantizationGrid::forBounds(Box3f()).step, 1e-3);  // no faces: any grid will do
}

// ---- round trips -------------------------------------------------------------------

TEST(GeometryCodec, RoundTripsRandomBatchesInEveryCodingWithinHalfAGridStep) {
  const Box3f box({-250.0f, -3.0f, -400.0f}, {350.0f, 90.0f, 100.0f});
  for (const QuantizationGrid& grid :
       {QuantizationGrid::forBounds(box), QuantizationGrid{glm::dvec3(box.lo), 0.25}}) {
    for (size_t n : {0, 1, 2, 3, 10, 17, 100, 1000, 5000})
      for (uint32_t seed = 1; seed <= 3; ++seed)
        for (const NamedCodings& c : everyCoding()) {
          SCOPED_TRACE(fmt::format("{} faces, seed {}, {}, step {}", n, seed, c.name, grid.step));
          const auto faces = randomBatch(n, seed, box, seed == 3);
          expectDecodesTo(faces, roundTrip(faces, grid, c.codings), grid);
        }
  }
}

TEST(GeometryCodec, RoundTripsRealFacesOfCity1AndDelfshaven) {
  for (const RealScene& s : realScenes())
    for (size_t n : {1, 10, 100, 1000, 10000})
      for (const glm::vec3& centre : centresIn(s.scene.bounds(), 3))
        for (const NamedCodings& c : everyCoding()) {
          SCOPED_TRACE(
              fmt::format("{}: {} faces near ({}, {}), {}", s.name, n, centre.x, centre.z, c.name));
          const auto faces = nearestFaces(s.faces, n, centre);
          expectDecodesTo(faces, roundTrip(faces, s.grid, c.codings), s.grid);
        }
}

TEST(GeometryCodec, CornersOutsideTheGridAreClampedOntoIt) {
  const QuantizationGrid grid{glm::dvec3(0.0), 1e-3};
  const std::vector<FaceTriangles> faces = {{5, 1, {{-1, 2, 3}, {1, -2, 3}, {1, 2, -3}}, {}, {}}};
  const DecodedGeometry g = roundTrip(faces, grid);
  ASSERT_EQ(g.indices.size(), 3u);
  for (uint32_t i : g.indices)
    EXPECT_GE(glm::min(glm::min(g.positions[i].x, g.positions[i].y), g.positions[i].z), 0.0f);
}

TEST(GeometryCodec, AnEmptyBatchRoundTrips) {
  const DecodedGeometry g = roundTrip({}, QuantizationGrid{});
  EXPECT_TRUE(g.faces.empty());
  EXPECT_TRUE(g.positions.empty());
}

TEST(GeometryCodec, PicksTheSmallestOfItsCodings) {
  for (const RealScene& s : realScenes())
    for (size_t n : {1, 10, 100, 1000})
      for (const glm::vec3& centre : centresIn(s.scene.bounds(), 3)) {
        const auto faces = nearestFaces(s.faces, n, centre);
        size_t smallest = std::numeric_limits<size_t>::max();
        for (const NamedCodings& c : everyCoding())
          if (std::string(c.name) != "chosen")
            smallest = std::min(smallest, encodeGeometry(faces, s.grid, c.codings).payload.size());
        EXPECT_EQ(encodeGeometry(faces, s.grid).payload.size(), smallest)
            << s.name << ", " << n << " faces";
      }
}

// Bytes a face on the wire (the whole frame, as a client counts them) for
// batches of n faces near points of each scene; printed for the record. The
// target (issue 13): at most 30 bytes a face, and small batches close to
// large ones.
TEST(GeometryCodec, ASmallBatchCostsAFaceLittleMoreThanALargeOne) {
  for (const RealScene& s : realScenes()) {
    std::map<size_t, double> perFace;
    std::map<std::string, std::map<size_t, double>> perCoding;
    const auto centres = centresIn(s.scene.bounds(), 8);
    for (size_t n : {1, 10, 100, 1000}) {
      size_t bytes = 0, faces = 0;
      std::map<std::string, size_t> codingBytes;
      for (const glm::vec3& centre : centres) {
        const auto batch = nearestFaces(s.faces, n, centre);
        faces += batch.size();
        for (const NamedCodings& c : everyCoding())
          codingBytes[c.name] += encodeMessage(encodeGeometry(batch, s.grid, c.codings)).size();
        bytes += encodeMessage(encodeGeometry(batch, s.grid)).size();
      }
      perFace[n] = double(bytes) / double(faces);
      for (const auto& [name, b] : codingBytes) perCoding[name][n] = double(b) / double(faces);
    }
    std::string table =
        fmt::format("{}: bytes a face by batch size (whole frames)\n{:>14}", s.name, "");
    for (const auto& [n, b] : perFace) table += fmt::format("{:>8}", n);
    for (const auto& [name, row] : perCoding) {
      table += fmt::format("\n{:>14}", name);
      for (const auto& [n, b] : row) table += fmt::format("{:>8.1f}", b);
    }
    std::printf("%s\n", table.c_str());
    // Every frame carries about 52 bytes of framing (length, Envelope,
    // table): a batch of one face cannot reach the target, ten can.
    EXPECT_LE(perFace[10], 30.0) << s.name;
    EXPECT_LE(perFace[100], 30.0) << s.name;
    EXPECT_LE(perFace[1000], 30.0) << s.name;
    EXPECT_LE(perFace[100], 2.0 * perFace[1000]) << s.name;
  }
}

// ---- bad input ----------------------------------------------------------------------

// A payload written by hand (varints as the schema describes them), to say
// exactly what is wrong with it.
struct Bytes {
  std::vector<uint8_t> bytes;
  Bytes& varint(uint64_t v) {
    do {
      bytes.push_back(uint8_t((v & 0x7f) | (v >= 0x80 ? 0x80 : 0)));
      v >>= 7;
    } while (v);
    return *this;
  }
  Bytes& raw(std::initializer_list<uint8_t> b) {
    bytes.insert(bytes.end(), b);
    return *this;
  }
};

std::string refusalOf(std::span<const uint8_t> payload, GeometryCodec codec = GeometryCodec::Varint,
                      GeometryCompression compression = GeometryCompression::None,
                      const QuantizationGrid& grid = {}) {
  DecodedGeometry out;
  std::string error;
  if (decodeGeometryPayload(payload, codec, compression, grid, out, error)) return "";
  EXPECT_FALSE(error.empty());
  EXPECT_TRUE(out.faces.empty() && out.positions.empty() && out.indices.empty());
  return error;
}

void expectRefusedSaying(std::span<const uint8_t> payload, const std::string& words,
                         GeometryCodec codec = GeometryCodec::Varint,
                         GeometryCompression compression = GeometryCompression::None) {
  const std::string error = refusalOf(payload, codec, compression);
  EXPECT_NE(error.find(words), std::string::npos)
      << "error: '" << error << "', expected '" << words << "'";
}

// One face (ID 7, material 2) with one triangle over vertices 0, 1, 2 in Varint.
Bytes oneTriangle() {
  Bytes p;
  p.varint(1).varint(3).varint(7).varint(1).varint(2).varint(1).varint(1);
  for (int v = 0; v < 3; ++v) p.varint(2 * uint64_t(v)).varint(0).varint(0);
  return p.varint(0).varint(0).varint(0);
}

TEST(GeometryCodec, DecodesAHandWrittenPayloadAsTheSchemaDescribesIt) {
  DecodedGeometry g;
  std::string error;
  const QuantizationGrid grid{glm::dvec3(10.0, 0.0, 0.0), 0.5};
  ASSERT_TRUE(decodeGeometryPayload(oneTriangle().bytes, GeometryCodec::Varint,
                                    GeometryCompression::None, grid, g, error))
      << error;
  EXPECT_EQ(g.faces, std::vector<uint32_t>{7});
  EXPECT_EQ(g.materials, std::vector<uint16_t>{2});
  EXPECT_EQ(g.triangleCounts, std::vector<uint16_t>{1});
  EXPECT_EQ(g.indices, (std::vector<uint32_t>{0, 1, 2}));
  // Zigzag deltas 0, +1, +2 grid steps along x.
  EXPECT_EQ(g.positions, (std::vector<glm::vec3>{{10.0f, 0, 0}, {10.5f, 0, 0}, {11.5f, 0, 0}}));
}

TEST(GeometryCodec, RejectsEveryTruncationOfAValidMessageInEveryCoding) {
  const auto faces = randomBatch(40, 5, Box3f({0, 0, 0}, {50, 20, 50}));
  const QuantizationGrid grid = QuantizationGrid::forBounds(Box3f({0, 0, 0}, {50, 20, 50}));
  for (const NamedCodings& c : everyCoding()) {
    const GeometryT g = encodeGeometry(faces, grid, c.codings);
    for (size_t n = 0; n < g.payload.size(); ++n) {
      DecodedGeometry out;
      std::string error;
      EXPECT_FALSE(decodeGeometryPayload(std::span(g.payload).first(n), g.codec, g.compression,
                                         grid, out, error))
          << c.name << ": " << n << " of " << g.payload.size() << " bytes decoded";
      EXPECT_FALSE(error.empty());
    }
  }
}

TEST(GeometryCodec, CorruptBytesAreRefusedOrDecodeToAConsistentBatch) {
  const Box3f box({0, 0, 0}, {50, 20, 50});
  const auto faces = randomBatch(60, 9, box);
  const QuantizationGrid grid = QuantizationGrid::forBounds(box);
  std::mt19937 rng(11);
  size_t refused = 0, tries = 0;
  for (const NamedCodings& c : everyCoding()) {
    const GeometryT g = encodeGeometry(faces, grid, c.codings);
    for (int trial = 0; trial < 400; ++trial, ++tries) {
      std::vector<uint8_t> bytes = g.payload;
      for (int flips = 1 + int(rng() % 4); flips > 0; --flips)
        bytes[rng() % bytes.size()] ^= uint8_t(1 + rng() % 255);
      DecodedGeometry out;
      std::string error;
      if (!decodeGeometryPayload(bytes, g.codec, g.compression, grid, out, error)) {
        EXPECT_FALSE(error.empty());
        ++refused;
        continue;
      }
      // Garbage may decode (the codecs carry no checksum), but never past its bounds.
      ASSERT_EQ(out.materials.size(), out.faces.size());
      ASSERT_EQ(out.triangleCounts.size(), out.faces.size());
      ASSERT_EQ(out.indices.size(), 3 * std::accumulate(out.triangleCounts.begin(),
                                                        out.triangleCounts.end(), size_t(0)));
      for (uint32_t i : out.indices) ASSERT_LT(i, out.positions.size());
      EXPECT_TRUE(std::is_sorted(out.faces.begin(), out.faces.end()));
    }
  }
  EXPECT_GT(refused, tries / 4);  // most corruption is caught, not just survived
}

TEST(GeometryCodec, RefusesCountsBeyondTheBytesThatCarryThem) {
  expectRefusedSaying(Bytes().varint(kMaxGeometryFaces + 1).bytes, "face count");
  expectRefusedSaying(Bytes().varint(1000).varint(0).varint(1).bytes, "face count");
  // 4 Mi vertices claimed, a vertex stream of 10 bytes.
  Bytes manyVertices;
  manyVertices.varint(1)
      .varint(kMaxGeometryVertices)
      .varint(0)
      .varint(1)
      .varint(0)
      .varint(1)
      .varint(0);
  Bytes meshopt = manyVertices;
  meshopt.varint(10).raw({0xa0, 0, 0, 0, 0, 0, 0, 0, 0, 0});
  expectRefusedSaying(meshopt.bytes, "cannot fit", GeometryCodec::Meshopt);
  manyVertices.raw({0, 0, 0, 0, 0, 0});
  expectRefusedSaying(manyVertices.bytes, "cannot fit");
  expectRefusedSaying(Bytes().varint(1).varint(kMaxGeometryVertices + 1).bytes, "vertex count");
  // 65 faces of 65535 triangles: over the index limit.
  Bytes triangles;
  triangles.varint(65).varint(0);
  for (int i = 0; i < 65; ++i) triangles.varint(1);
  triangles.varint(65).varint(0).varint(65).varint(65535);
  expectRefusedSaying(triangles.bytes, "more than the limit");
  // A run longer than the faces left, and a run of length 0.
  expectRefusedSaying(Bytes().varint(2).varint(0).varint(1).varint(1).varint(3).varint(0).bytes,
                      "material run");
  expectRefusedSaying(Bytes().varint(2).varint(0).varint(1).varint(1).varint(0).varint(0).bytes,
                      "length 0");
  // A material beyond 16 bits.
  expectRefusedSaying(Bytes().varint(1).varint(0).varint(1).varint(1).varint(70000).bytes,
                      "material run");
}

TEST(GeometryCodec, RefusesIndicesPastTheVertices) {
  // One vertex, one triangle whose corners are "new" three times: 0, 1, 2.
  Bytes p;
  p.varint(1).varint(1).varint(0).varint(1).varint(0).varint(1).varint(1);
  p.varint(0).varint(0).varint(0).varint(0).varint(0).varint(0);
  expectRefusedSaying(p.bytes, "index 1 past 1 vertices");
  // A back reference before the first vertex.
  Bytes back;
  back.varint(1).varint(1).varint(0).varint(1).varint(0).varint(1).varint(1);
  back.varint(0).varint(0).varint(0).varint(0).varint(2).varint(0);
  expectRefusedSaying(back.bytes, "an index");
}

TEST(GeometryCodec, RefusesFaceIdsBeyond32BitsAndTrailingBytes) {
  Bytes ids;
  ids.varint(2)
      .varint(0)
      .varint(1)
      .varint(0xffffffffu)
      .varint(1)
      .varint(2)
      .varint(0)
      .varint(2)
      .varint(0);
  expectRefusedSaying(ids.bytes, "face ID");
  Bytes trailing = oneTriangle();
  trailing.raw({0});
  expectRefusedSaying(trailing.bytes, "after the last field");
  // A vertex coordinate walking off the grid (below 0).
  Bytes off;
  off.varint(1)
      .varint(1)
      .varint(0)
      .varint(1)
      .varint(0)
      .varint(1)
      .varint(0)
      .varint(1)
      .varint(0)
      .varint(0);
  expectRefusedSaying(off.bytes, "off the grid");
}

TEST(GeometryCodec, RefusesUnknownCodecsAndCompressionsAndABadGrid) {
  const auto bytes = oneTriangle().bytes;
  expectRefusedSaying(bytes, "unknown codec", GeometryCodec(7));
  expectRefusedSaying(bytes, "unknown compression", GeometryCodec::Varint, GeometryCompression(9));
  for (const QuantizationGrid& grid :
       {QuantizationGrid{glm::dvec3(0.0), 0.0}, QuantizationGrid{glm::dvec3(0.0), -1.0},
        QuantizationGrid{glm::dvec3(NAN, 0.0, 0.0), 1e-3}})
    EXPECT_NE(refusalOf(bytes, GeometryCodec::Varint, GeometryCompression::None, grid).find("grid"),
              std::string::npos);
}

TEST(GeometryCodec, AMessageWithNoPayloadIsRefused) {
  flatbuffers::FlatBufferBuilder b;
  GeometryBuilder gb(b);
  const auto geometry = gb.Finish();
  b.Finish(CreateEnvelope(b, Payload::Geometry, geometry.Union()));
  const std::vector<uint8_t> frame(b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize());
  DecodedGeometry g;
  std::string error;
  EXPECT_FALSE(decodeGeometry(geometryIn(frame), QuantizationGrid{}, g, error));
  EXPECT_NE(error.find("face count"), std::string::npos) << error;
}

// zstd frames: the size is bounded from the header before anything is allocated.
std::vector<uint8_t> zstdOf(std::span<const uint8_t> raw) {
  std::vector<uint8_t> out(ZSTD_compressBound(raw.size()));
  out.resize(ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 1));
  return out;
}

TEST(GeometryCodec, RefusesAZstdBombBeforeDecompressingIt) {
  const std::vector<uint8_t> zeros(kMaxGeometryPayloadBytes + 1, 0);
  const std::vector<uint8_t> bomb = zstdOf(zeros);
  ASSERT_LT(bomb.size(), 4096u);  // a few KiB claiming 32 MiB
  expectRefusedSaying(bomb, "more than the limit", GeometryCodec::Varint,
                      GeometryCompression::Zstd);
}

TEST(GeometryCodec, RefusesZstdFramesThatHoldMoreThanTheyClaimOrDoNotSay) {
  const auto raw = oneTriangle().bytes;
  // Two frames: the first header's size is less than both hold.
  std::vector<uint8_t> two = zstdOf(raw);
  const std::vector<uint8_t> second = zstdOf(raw);
  two.insert(two.end(), second.begin(), second.end());
  expectRefusedSaying(two, "does not decompress", GeometryCodec::Varint, GeometryCompression::Zstd);
  // A frame written as a stream, without its size.
  ZSTD_CCtx* c = ZSTD_createCCtx();
  std::vector<uint8_t> stream(ZSTD_compressBound(raw.size()) + 64);
  ZSTD_inBuffer in{raw.data(), raw.size(), 0};
  ZSTD_outBuffer out{stream.data(), stream.size(), 0};
  ZSTD_compressStream2(c, &out, &in, ZSTD_e_continue);
  ASSERT_EQ(ZSTD_compressStream2(c, &out, &in, ZSTD_e_end), 0u);
  ZSTD_freeCCtx(c);
  stream.resize(out.pos);
  expectRefusedSaying(stream, "does not state its size", GeometryCodec::Varint,
                      GeometryCompression::Zstd);
  // Not zstd at all.
  expectRefusedSaying(raw, "not a zstd frame", GeometryCodec::Varint, GeometryCompression::Zstd);
  // And the honest frame decodes.
  EXPECT_EQ(refusalOf(zstdOf(raw), GeometryCodec::Varint, GeometryCompression::Zstd), "");
}

}  // namespace
}  // namespace vistream::wire

namespace vistream::wire {
namespace {

// Faces of 1 to 3 triangles, each with a lighting grid of level 1 to 8 whose
// colours are random bytes, or random multiples of `step` (and 255).
std::vector<FaceTriangles> litFaces(uint32_t seed, uint32_t step) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> byte(0, 255), level(1, 8), count(1, 3);
  std::vector<FaceTriangles> faces;
  for (uint32_t f = 0; f < 40; ++f) {
    FaceTriangles face{(f * 7919u) % 1000u, 0, {}, {}, {}};
    for (int t = count(rng); t > 0; --t) {
      for (int k = 0; k < 3; ++k)
        face.corners.push_back(glm::vec3(float(byte(rng)), float(byte(rng)), float(f)));
      const uint32_t n = uint32_t(level(rng));
      face.levels.push_back(uint8_t(n));
      for (uint32_t p = 0; p < (n + 1) * (n + 2) / 2; ++p) {
        glm::u8vec3 c(uint8_t(byte(rng)), uint8_t(byte(rng)), uint8_t(byte(rng)));
        for (int a = 0; a < 3; ++a)
          c[a] = uint8_t(std::min(255u, (uint32_t(c[a]) + step / 2) / step * step));
        face.colours.push_back(c);
      }
    }
    faces.push_back(std::move(face));
  }
  return faces;
}

// The decoded grids are the input's, face by face in ID order.
void expectSameLighting(std::vector<FaceTriangles> input, const DecodedGeometry& g) {
  std::stable_sort(input.begin(), input.end(),
                   [](const FaceTriangles& a, const FaceTriangles& b) { return a.face < b.face; });
  std::vector<uint8_t> levels;
  std::vector<glm::u8vec3> colours;
  for (const FaceTriangles& f : input) {
    levels.insert(levels.end(), f.levels.begin(), f.levels.end());
    colours.insert(colours.end(), f.colours.begin(), f.colours.end());
  }
  EXPECT_EQ(g.levels, levels);
  EXPECT_EQ(g.colours, colours);
}

TEST(GeometryLighting, RandomGridsRoundTripExactlyAtEveryColourStep) {
  const QuantizationGrid grid{glm::dvec3(0.0), 1e-3};
  for (uint32_t step : {1u, 2u, 4u, 16u}) {
    const auto faces = litFaces(step, step);
    const DecodedGeometry g = roundTrip(faces, grid);
    expectSameLighting(faces, g);
  }
}

TEST(GeometryLighting, ABatchWithAFaceWithoutLightingCarriesNone) {
  auto faces = litFaces(3, 4);
  faces[5].levels.clear();
  faces[5].colours.clear();
  const GeometryT g = encodeGeometry(faces, QuantizationGrid{});
  EXPECT_TRUE(g.lighting.empty());
  const DecodedGeometry d = roundTrip(faces, QuantizationGrid{});
  EXPECT_TRUE(d.levels.empty());
  EXPECT_TRUE(d.colours.empty());
}

TEST(GeometryLighting, EveryTruncationAndABadHeaderAreRefusedWithAReason) {
  const auto faces = litFaces(4, 4);
  const GeometryT g = encodeGeometry(faces, QuantizationGrid{});
  size_t triangles = 0;
  for (const auto& f : faces) triangles += f.levels.size();
  ASSERT_FALSE(g.lighting.empty());
  DecodedGeometry out;
  std::string error;
  ASSERT_TRUE(decodeGeometryLighting(g.lighting, triangles, out, error)) << error;
  for (size_t n = 0; n < g.lighting.size(); n += std::max<size_t>(1, g.lighting.size() / 50)) {
    error.clear();
    EXPECT_FALSE(decodeGeometryLighting(std::span(g.lighting.data(), n), triangles, out, error))
        << n;
    EXPECT_FALSE(error.empty());
    EXPECT_TRUE(out.colours.empty());
  }
  // One triangle more than the bytes hold, an unknown format, a step of 3.
  EXPECT_FALSE(decodeGeometryLighting(g.lighting, triangles + 1, out, error));
  std::vector<uint8_t> bad = g.lighting;
  bad[0] = 7;
  EXPECT_FALSE(decodeGeometryLighting(bad, triangles, out, error));
  EXPECT_NE(error.find("format"), std::string::npos) << error;
  const std::vector<uint8_t> step3 = {0, 3, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_FALSE(decodeGeometryLighting(step3, 1, out, error));
  EXPECT_NE(error.find("power of 2"), std::string::npos) << error;
}

TEST(GeometryLighting, ARawSectionWrittenByHandDecodesAsTheSchemaSays) {
  // Raw format, step 4, one triangle of level 1: lattice indices (10, 20, 30)
  // coded as green 20 and red, blue minus green (-10, +10); the next point is
  // predicted from the one before it: residual 0 repeats it, then +1 green.
  const std::vector<uint8_t> bytes = {0, 4, 1, 20, uint8_t(-10), 10, 0, 0, 0, 1, 0, 0};
  DecodedGeometry out;
  std::string error;
  ASSERT_TRUE(decodeGeometryLighting(bytes, 1, out, error)) << error;
  ASSERT_EQ(out.levels, std::vector<uint8_t>{1});
  ASSERT_EQ(out.colours.size(), 3u);
  EXPECT_EQ(out.colours[0], glm::u8vec3(40, 80, 120));
  EXPECT_EQ(out.colours[1], glm::u8vec3(40, 80, 120));
  EXPECT_EQ(out.colours[2], glm::u8vec3(44, 84, 124));
}

}  // namespace
}  // namespace vistream::wire
