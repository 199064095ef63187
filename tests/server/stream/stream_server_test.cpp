// The streaming server over real loopback sockets: the conversation, what is
// streamed (checked against rays cast into the scene), and every kind of bad
// client, each ending only its own session.
#include "server/stream/stream_server.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "common/generate/path.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene_loader.h"
#include "common/world/static_world.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/temp_dir.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream {
namespace {

using testing::configWith;
using testing::nextErrorCode;
using testing::Received;
using testing::receiveUntilReady;
using testing::ServerFixture;
using testing::TestClient;
using wire::ErrorCode;
using wire::Payload;

// A new client joins with a near-field radius of `radiusM`, stands at `eye`
// looking along `yawDeg` and reads until the eye's cell is ready (`ready`
// stays false if the Welcome or the CellReady never came).
Received joinAndLoad(ServerFixture& fx, const glm::dvec3& eye, float radiusM, float yawDeg = 0.0f) {
  TestClient c(fx.port());
  EXPECT_TRUE(c.join("", wire::kProtocolVersion, radiusM));
  c.pose(eye, yawDeg);
  return receiveUntilReady(c, *fx.world().cellOf(glm::vec3(eye)),
                           wire::QuantizationGrid::forBounds(fx.world().scene().bounds()));
}

// What the server should stream for a cell, computed here: the PVS of the
// cell's box, cut to the faces whose bounds lie within the radius.
std::set<uint32_t> expectedFaceSet(const Scene& scene, const Box3f& cell, float radius, bool pvs) {
  std::vector<Box3f> boxes(scene.faceCount);
  for (const Object& o : scene.objects)
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k)
        boxes[o.mesh.faceIds[t]].extend(o.mesh.positions[o.mesh.triangles[t][k]]);
  std::set<uint32_t> out;
  std::vector<uint32_t> candidates;
  if (pvs) {
    candidates = EpsilonPvs(scene).compute(cell).faces;
  } else {
    for (uint32_t f = 0; f < scene.faceCount; ++f) candidates.push_back(f);
  }
  for (uint32_t f : candidates) {
    const glm::vec3 gap =
        glm::max(glm::vec3(0.0f), glm::max(boxes[f].lo - cell.hi, cell.lo - boxes[f].hi));
    if (glm::length(gap) <= radius) out.insert(f);
  }
  return out;
}

// Faces hit by a 64 x 64 fan of rays in every horizontal direction from eye.
std::set<uint32_t> facesSeenFrom(const Scene& scene, const glm::vec3& eye, float radius) {
  const FlatTriangles tris = flattenScene(scene, true);
  const auto rays = makeEmbreeRayQuery(tris);
  std::set<uint32_t> seen;
  for (int a = 0; a < 256; ++a)
    for (int b = 0; b < 32; ++b) {
      const float az = 6.2831853f * float(a) / 256.0f, el = -0.6f + 1.2f * float(b) / 31.0f;
      const glm::vec3 d(std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az));
      const Hit h = rays->firstHit(Ray{eye, d, 0.0f, radius});
      if (h.valid()) seen.insert(tris.faceIds[h.triangle]);
    }
  return seen;
}

// A welcomed client that stands in the street gets geometry.
void expectServed(TestClient& c) {
  c.pose({0.0, 1.7, 8.0});
  EXPECT_TRUE(c.nextOf(Payload::Geometry)) << "a session was not served";
}

// A fresh client can still connect, say Hello and get geometry.
void expectOthersStillServed(ServerFixture& fx) {
  TestClient c(fx.port());
  ASSERT_TRUE(c.join());
  expectServed(c);
}

// Expects `bad` to get an Error with `code`, and a client that connects after
// it to be served: the error ended only the session that caused it.
void expectOnlyItsSessionRefused(ServerFixture& fx, TestClient& bad, ErrorCode code) {
  EXPECT_EQ(nextErrorCode(bad), code);
  expectOthersStillServed(fx);
}

TEST(StreamServer, GreetsAHelloWithTheSceneItsGridAndMaterials) {
  ServerFixture fx;
  TestClient c(fx.port());
  c.hello("", wire::kProtocolVersion, 50.0f);
  const auto f = c.nextOf(Payload::Welcome);
  ASSERT_TRUE(f);
  const wire::Welcome& w = *wire::envelopeOf(*f)->payload_as_Welcome();
  EXPECT_EQ(w.protocol_version(), wire::kProtocolVersion);
  EXPECT_EQ(w.scene_id()->str(), "street");
  EXPECT_EQ(w.face_count(), fx.world().faceCount());
  EXPECT_EQ(w.near_field_radius_m(), 50.0f);
  EXPECT_EQ(wire::fromWire(*w.grid()->dims()), fx.world().grid().dims());
  EXPECT_EQ(w.materials()->size(), fx.world().scene().materials.size());
  EXPECT_EQ(w.policy()->str(), "visibility");
}

TEST(StreamServer, StreamsTheCellsPvsWithinTheRadiusOnceThenSaysCellReady) {
  ServerFixture fx;
  const glm::dvec3 eye(0.5, 1.7, 8.5);
  const glm::ivec3 cell = *fx.world().cellOf(glm::vec3(eye));
  const Received r = joinAndLoad(fx, eye, 40.0f);
  ASSERT_TRUE(r.ready);
  const std::set<uint32_t> held = r.held();
  EXPECT_EQ(held.size(), r.faces.size()) << "a face was sent twice";
  const Scene& scene = fx.world().scene();
  const Box3f box = fx.world().grid().cellBox(cell);
  for (uint32_t f : expectedFaceSet(scene, box, 40.0f, true))
    EXPECT_TRUE(held.count(f)) << "face " << f;
  // The independent oracle: every face a ray from the eye hits within the radius is held.
  for (uint32_t f : facesSeenFrom(scene, glm::vec3(eye), 40.0f))
    EXPECT_TRUE(held.count(f)) << "seen face " << f;
  // Known hidden: the boxes north of the 6 m wall are not sent.
  size_t northHeld = 0;
  for (const Object& o : scene.objects)
    if (o.name.rfind("north_", 0) == 0)
      for (uint32_t id : o.mesh.faceIds) northHeld += held.count(id);
  EXPECT_EQ(northHeld, 0u);
  // Decoded corners lie within the quantization step of the scene's.
  std::vector<std::vector<glm::vec3>> corners(scene.faceCount);
  for (const Object& o : scene.objects)
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k)
        corners[o.mesh.faceIds[t]].push_back(o.mesh.positions[o.mesh.triangles[t][k]]);
  for (const auto& g : r.batches) {
    size_t tri = 0;
    for (size_t i = 0; i < g.faces.size(); ++i)
      for (uint16_t t = 0; t < g.triangleCounts[i]; ++t, ++tri) {
        // The index codec may rotate a triangle's corners (keeping its winding).
        float best = 1e30f;
        for (int rot = 0; rot < 3; ++rot) {
          float worst = 0.0f;
          for (int k = 0; k < 3; ++k) {
            const glm::vec3 p = g.positions[g.indices[3 * tri + size_t(k)]];
            const glm::vec3 q = corners[g.faces[i]][3 * t + size_t((k + rot) % 3)];
            worst = std::max(worst, glm::length(p - q));
          }
          best = std::min(best, worst);
        }
        EXPECT_LT(best, 0.01f) << "face " << g.faces[i];
      }
  }
}

TEST(StreamServer, FacesSeenFromThePoseArriveBeforeFacesBehindTheViewer) {
  // The box behind the viewer has the lowest face IDs, so only the
  // visible-first order can send it after the boxes in view.
  Scene scene;
  testing::addGround(scene, -40, -40, 40, 40);
  const uint32_t behind = testing::addBox(scene, "behind", {-2, 0, 34}, {2, 3, 38});
  // Enough objects on both sides that the kD-tree separates front and back.
  for (int i = 0; i < 8; ++i)
    testing::addBox(scene, "ahead_" + std::to_string(i), {-20.0f + 5.0f * float(i), 0, -12},
                    {-17.0f + 5.0f * float(i), 3, -9});
  for (int i = 0; i < 8; ++i)
    testing::addBox(scene, "back_" + std::to_string(i), {-20.0f + 5.0f * float(i), 0, 24},
                    {-17.0f + 5.0f * float(i), 3, 27});
  finalizeScene(scene);
  scene.name = "ahead";
  StreamServerConfig cfg;
  cfg.batchBytes = 400;  // about five faces a frame, so the order shows
  ServerFixture fx(cfg, std::move(scene));
  const glm::dvec3 eye(0.5, 1.7, 5.5);
  const Received r = joinAndLoad(fx, eye, 60.0f, 0.0f);  // looking along -Z at the boxes ahead
  ASSERT_TRUE(r.ready);
  // Faces that rays through the 60-degree frustum hit.
  const FlatTriangles tris = flattenScene(fx.world().scene(), true);
  const auto rays = makeEmbreeRayQuery(tris);
  std::set<uint32_t> seen;
  const double th = std::tan(30.0 * 3.14159265358979323846 / 180.0);
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 32; ++x) {
      const glm::vec3 d(float(th * ((x + 0.5) / 16.0 - 1.0)),
                        float(0.75 * th * ((y + 0.5) / 12.0 - 1.0)), -1.0f);
      const Hit h = rays->firstHit(Ray{glm::vec3(eye), glm::normalize(d), 0.0f, 60.0f});
      if (h.valid()) seen.insert(tris.faceIds[h.triangle]);
    }
  // By frame: a Geometry frame is taken up whole, and lists its faces by ID
  // (protocol version 2), so order shows between frames, not within one.
  size_t lastSeen = 0, firstBehind = r.batches.size();
  for (size_t b = 0; b < r.batches.size(); ++b)
    for (uint32_t f : r.batches[b].faces) {
      if (seen.count(f)) lastSeen = b;
      if (f >= behind && f < behind + 6) firstBehind = std::min(firstBehind, b);
    }
  ASSERT_GT(seen.size(), 6u);
  ASSERT_LT(firstBehind, r.batches.size())
      << "the box behind is within the radius and must come eventually";
  EXPECT_LE(lastSeen, firstBehind)
      << "a frame with a face behind the viewer came before one in view";
}

TEST(StreamServer, RadiusPolicyStreamsEverythingWithinTheRadiusVisibleOrNot) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.policy = StreamPolicy::Radius; }));
  const glm::dvec3 eye(0.5, 1.7, 8.5);
  const glm::ivec3 cell = *fx.world().cellOf(glm::vec3(eye));
  const Received r = joinAndLoad(fx, eye, 40.0f);
  ASSERT_TRUE(r.ready);
  const std::set<uint32_t> held = r.held();
  const auto expected =
      expectedFaceSet(fx.world().scene(), fx.world().grid().cellBox(cell), 40.0f, false);
  for (uint32_t f : expected) EXPECT_TRUE(held.count(f)) << "face " << f;
  EXPECT_GT(
      expected.size(),
      expectedFaceSet(fx.world().scene(), fx.world().grid().cellBox(cell), 40.0f, true).size());
}

TEST(StreamServer, PrefetchesTheCellsAheadSoTheyAreReadyBeforeTheClientArrives) {
  ServerFixture fx;
  TestClient c(fx.port());
  ASSERT_TRUE(c.join("", wire::kProtocolVersion, 40.0f));
  const glm::dvec3 eye(0.5, 1.7, 8.5);
  c.pose(eye, 90.0f, {-1.4f, 0.0f, 0.0f});  // walking west
  const glm::ivec3 cell = *fx.world().cellOf(glm::vec3(eye));
  const glm::ivec3 ahead = *fx.world().cellOf(glm::vec3(eye) + glm::vec3(-4.0f, 0.0f, 0.0f));
  ASSERT_NE(ahead, cell);
  std::set<glm::ivec3, bool (*)(const glm::ivec3&, const glm::ivec3&)> ready(
      [](const glm::ivec3& a, const glm::ivec3& b) {
        return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
      });
  for (int i = 0; i < 200 && !(ready.count(ahead) && ready.count(cell)); ++i) {
    auto f = c.next(0.1);
    if (f && wire::envelopeOf(*f)->payload_type() == Payload::CellReady)
      for (const glm::ivec3& announced :
           wire::readyCells(*wire::envelopeOf(*f)->payload_as_CellReady()))
        ready.insert(announced);
  }
  EXPECT_TRUE(ready.count(cell));
  EXPECT_TRUE(ready.count(ahead)) << "the cell ahead was not prefetched";
}

TEST(StreamServer, AClientOverItsMemoryBudgetGetsEvictionsAndStaysWithinIt) {
  ServerFixture fx;
  TestClient c(fx.port());
  // Less than two stops' cells need (neighbour prefetch takes in only the
  // cells within a second's walk, so 2,500 bytes no longer overflowed).
  const uint64_t budget = 1200;
  ASSERT_TRUE(c.join("", wire::kProtocolVersion, 10.0f, budget));
  std::set<uint32_t> held;
  size_t evictions = 0;
  const auto grid = wire::QuantizationGrid::forBounds(fx.world().scene().bounds());
  for (double x : {-24.0, -8.0, 8.0, 24.0}) {
    c.pose({x, 1.7, 8.5});
    for (int i = 0; i < 20; ++i) {
      auto f = c.next(0.1);
      if (!f) continue;
      const auto* e = wire::envelopeOf(*f);
      if (e->payload_type() == Payload::Geometry) {
        wire::DecodedGeometry g;
        std::string error;
        ASSERT_TRUE(wire::decodeGeometry(*e->payload_as_Geometry(), grid, g, error)) << error;
        held.insert(g.faces.begin(), g.faces.end());
      } else if (e->payload_type() == Payload::Evict) {
        ++evictions;
        for (uint32_t id : *e->payload_as_Evict()->face_ids()) held.erase(id);
      }
    }
    uint64_t bytes = 0;
    for (uint32_t id : held) bytes += fx.world().faceBytes(id);
    EXPECT_LE(bytes, budget) << "at x = " << x;
  }
  EXPECT_GT(evictions, 0u);
}

TEST(StreamServer, BandwidthLimitBoundsTheBytesEachClientReceives) {
  StreamServerConfig cfg;
  cfg.maxClientKbps = 40.0;  // 5,000 bytes a second
  cfg.batchBytes = 2048;
  cfg.policy = StreamPolicy::Radius;  // every face within the radius
  // More geometry than 2 s at the limit, even coded compactly (protocol 2
  // sends the whole street in under 2 KB): 900 boxes of irregular sizes.
  Scene field;
  testing::addGround(field, -31, -31, 31, 31);
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j) {
      const float x = -29.0f + 2.0f * float(i), z = -29.0f + 2.0f * float(j);  // (0.5, 8.5) free
      testing::addBox(
          field, fmt::format("box_{}_{}", i, j), {x, 0, z},
          {x + 0.6f + 0.013f * float((i * 7 + j) % 23), 1.0f + 0.21f * float((i + j) % 7),
           z + 0.6f + 0.017f * float((i + 3 * j) % 19)});
    }
  finalizeScene(field);
  field.name = "field";
  ServerFixture fx(cfg, std::move(field));
  TestClient c(fx.port());
  ASSERT_TRUE(c.join("", wire::kProtocolVersion, 60.0f));
  c.pose({0.5, 1.7, 8.5});
  const auto start = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - start < std::chrono::seconds(2)) c.next(0.1);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // The bucket holds at most max(a quarter second, one batch) of credit, and
  // a frame may overdraw it by its own size.
  EXPECT_LE(double(c.bytes()), 5000.0 * s + 2048.0 + 4096.0 + 2000.0);
  EXPECT_GT(c.bytes(), 2000u);
}

TEST(StreamServer, PvsOnlyModeAnswersRequestsAndSendsNoGeometry) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.pvsOnly = true; }));
  TestClient c(fx.port());
  c.hello();
  const auto w = c.nextOf(Payload::Welcome);
  ASSERT_TRUE(w);
  EXPECT_TRUE(wire::envelopeOf(*w)->payload_as_Welcome()->pvs_only());
  const glm::dvec3 point(5.0, 1.7, 10.0);
  wire::PvsRequestT req;
  req.request_id = 42;
  req.point = std::make_unique<wire::Vec3d>(wire::toWire(point));
  c.sendRaw(wire::encodeMessage(std::move(req)));
  const auto f = c.nextOf(Payload::PvsReply);
  ASSERT_TRUE(f);
  const wire::PvsReply& reply = *wire::envelopeOf(*f)->payload_as_PvsReply();
  EXPECT_EQ(reply.request_id(), 42u);
  ASSERT_TRUE(reply.found());
  const glm::ivec3 cell = *fx.world().cellOf(glm::vec3(point));
  EXPECT_EQ(wire::fromWire(*reply.cell()), cell);
  const auto expected =
      EpsilonPvs(fx.world().scene()).compute(fx.world().grid().cellBox(cell)).faces;
  EXPECT_EQ(std::vector<uint32_t>(reply.face_ids()->begin(), reply.face_ids()->end()), expected);
  // Outside the grid: found is false.
  wire::PvsRequestT far;
  far.request_id = 43;
  far.point = std::make_unique<wire::Vec3d>(wire::toWire(glm::dvec3(1e6, 0.0, 0.0)));
  c.sendRaw(wire::encodeMessage(std::move(far)));
  const auto g = c.nextOf(Payload::PvsReply);
  ASSERT_TRUE(g);
  EXPECT_FALSE(wire::envelopeOf(*g)->payload_as_PvsReply()->found());
  c.pose(point);
  EXPECT_FALSE(c.nextOf(Payload::Geometry, 1.0));
}

TEST(StreamServer, ServesPvsFromABakedDatabaseAndRejectsADatabaseOfAnotherScene) {
  testing::TempDir dir;
  const auto db = dir.path() / "street.db";
  {
    const Scene scene = testing::streetScene();
    // The server's own recipe, so the bake covers the cells it serves.
    const FreeSpace fs = buildStaticWorld(scene).freeSpace;
    BakeOptions bo;
    bo.cellSize = glm::vec3(4.0f, 2.0f, 4.0f);
    bo.threads = 1;
    bakePvs(scene, EpsilonPvs(scene), fs, bo, db);
  }
  StreamWorldOptions wo;
  wo.pvsDatabase = db;
  ServerFixture fx({}, testing::streetScene(), wo);
  const PvsDatabase baked = PvsDatabase::open(db);
  EXPECT_EQ(fx.world().grid().dims(), baked.header().dims);
  TestClient c(fx.port());
  ASSERT_TRUE(c.join());
  const uint32_t linear = baked.cellIndices().front();
  wire::PvsRequestT req;
  req.by_cell = true;
  req.cell = std::make_unique<wire::CellIndex>(wire::toWire(fx.world().grid().cellAt(linear)));
  c.sendRaw(wire::encodeMessage(std::move(req)));
  const auto f = c.nextOf(Payload::PvsReply);
  ASSERT_TRUE(f);
  const auto* ids = wire::envelopeOf(*f)->payload_as_PvsReply()->face_ids();
  EXPECT_EQ(std::vector<uint32_t>(ids->begin(), ids->end()), *baked.cell(linear));
  EXPECT_EQ(fx.world().cacheStats().pvsFromDatabase, 1u);
  // Another scene: a clear error naming the database.
  Scene other = testing::streetScene();
  testing::addBox(other, "extra", {0, 0, 25}, {1, 1, 26});
  finalizeScene(other);
  try {
    StreamWorld w(std::move(other), wo);
    ADD_FAILURE() << "a database of another scene was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("street.db"), std::string::npos) << e.what();
  }
}

TEST(StreamServer, AvatarsGoOnlyToClientsThatCanSeeThemAndWantThem) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.avatarHz = 20.0; }));
  TestClient a(fx.port()), b(fx.port()), hidden(fx.port()), blind(fx.port());
  a.hello();
  b.hello();
  hidden.hello();
  blind.hello("", wire::kProtocolVersion, 0.0f, 0, false);
  uint32_t ids[4];
  TestClient* all[] = {&a, &b, &hidden, &blind};
  for (int i = 0; i < 4; ++i) {
    const auto w = all[i]->nextOf(Payload::Welcome);
    ASSERT_TRUE(w);
    ids[i] = wire::envelopeOf(*w)->payload_as_Welcome()->session_id();
  }
  a.pose({-10.0, 1.7, 8.0});
  b.pose({10.0, 1.7, 8.0});        // same side of the wall
  hidden.pose({0.0, 1.7, -25.0});  // behind the wall, by the north boxes
  blind.pose({12.0, 1.7, 8.0});
  bool aSeesB = false, aSeesHidden = false;
  for (int i = 0; i < 30; ++i) {
    for (TestClient* c : {&b, &hidden, &blind}) c->next(0.01);
    auto f = a.nextOf(Payload::Avatar, 0.2);
    // A frame may only list departures (no `avatars` vector at all).
    const auto* states = f ? wire::envelopeOf(*f)->payload_as_Avatar()->avatars() : nullptr;
    if (!states) continue;
    for (const auto* s : *states) {
      aSeesB |= s->session_id() == ids[1];
      aSeesHidden |= s->session_id() == ids[2];
    }
  }
  EXPECT_TRUE(aSeesB);
  EXPECT_FALSE(aSeesHidden) << "an avatar behind the wall was sent";
  EXPECT_FALSE(blind.nextOf(Payload::Avatar, 0.5)) << "a client that wants no avatars got some";
}

// The server offers the Fox: Welcome names it with its size and the light
// avatars are shaded with; asking for it returns the file's bytes (which
// load as the same model); asking again, or for a model not offered, ends
// only that session. A user walking at 1.4 m/s is reported walking, its
// phase growing with time.
TEST(StreamServer, OffersAvatarModelsSendsEachOnceAndReportsGaitAndPhase) {
  const std::filesystem::path fox = std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb";
  ServerFixture fx(configWith([&](StreamServerConfig& c) {
    c.avatarHz = 20.0;
    c.avatarModels = std::make_shared<const AvatarCatalogue>(
        AvatarCatalogue::load({fox}, 1.1f, testing::streetScene()));
  }));
  TestClient a(fx.port()), b(fx.port());
  a.hello();
  b.hello();
  const auto w = a.nextOf(Payload::Welcome);
  ASSERT_TRUE(w);
  const wire::Welcome* welcome = wire::envelopeOf(*w)->payload_as_Welcome();
  ASSERT_TRUE(welcome->avatar_models());
  ASSERT_EQ(welcome->avatar_models()->size(), 1u);
  EXPECT_EQ(welcome->avatar_models()->Get(0)->name()->str(), "Fox.glb");
  EXPECT_EQ(welcome->avatar_models()->Get(0)->bytes(), std::filesystem::file_size(fox));
  EXPECT_FLOAT_EQ(welcome->avatar_models()->Get(0)->height_m(), 1.1f);
  ASSERT_TRUE(welcome->avatar_light());
  EXPECT_EQ(welcome->avatar_light()->size(), 100u);
  ASSERT_TRUE(b.nextOf(Payload::Welcome));

  wire::AvatarModelRequestT request;
  request.model = 0;
  a.sendRaw(wire::encodeMessage(wire::AvatarModelRequestT(request)));
  const auto data = a.nextOf(Payload::AvatarModelData);
  ASSERT_TRUE(data);
  const auto* glb = wire::envelopeOf(*data)->payload_as_AvatarModelData()->glb();
  ASSERT_TRUE(glb);
  const std::string bytes(reinterpret_cast<const char*>(glb->data()), glb->size());
  std::ifstream in(fox, std::ios::binary);
  const std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(bytes, file);
  EXPECT_EQ(
      AvatarModel::fromScene(loadGlbFromMemory(bytes, "Fox.glb"), "Fox.glb", 1.0f).triangleCount(),
      576u);

  // b walks east at 1.4 m/s; a watches from the same street.
  a.pose({-10.0, 1.7, 8.0}, 90.0f);
  std::vector<float> phases;
  for (int i = 0; i < 40 && phases.size() < 6; ++i) {
    b.pose({0.0 + 0.07 * i, 1.7, 8.0}, -90.0f, glm::vec3(1.4f, 0.0f, 0.0f));
    auto f = a.nextOf(Payload::Avatar, 0.1);
    // A frame may only list departures (no `avatars` vector at all).
    const auto* states = f ? wire::envelopeOf(*f)->payload_as_Avatar()->avatars() : nullptr;
    if (!states) continue;
    for (const auto* s : *states) {
      EXPECT_EQ(s->gait(), wire::AvatarGait::Walk);
      EXPECT_NEAR(s->speed_mps(), 1.4f, 1e-4f);
      EXPECT_EQ(s->model(), 0u);
      phases.push_back(s->phase_s());
    }
  }
  ASSERT_GE(phases.size(), 3u);
  EXPECT_GT(phases.back(), phases.front());

  a.sendRaw(wire::encodeMessage(wire::AvatarModelRequestT(request)));  // again
  EXPECT_EQ(nextErrorCode(a), ErrorCode::RateLimited);
  request.model = 1;  // not offered
  b.sendRaw(wire::encodeMessage(wire::AvatarModelRequestT(request)));
  EXPECT_EQ(nextErrorCode(b), ErrorCode::BadRequest);
  expectOthersStillServed(fx);
}

// ---- bad input: each ends only its own session ---------------------------------

TEST(StreamServer, WrongProtocolVersionGetsUnsupportedVersionAndIsClosed) {
  ServerFixture fx;
  TestClient bad(fx.port());
  bad.hello("", 99);
  expectRefusedAndClosed(bad, ErrorCode::UnsupportedVersion);
  expectOthersStillServed(fx);
}

TEST(StreamServer, APeerOfTheOldProtocolVersionGetsAnErrorNamingBothVersionsAndIsClosed) {
  // Version 1 sent Geometry in a layout version 2 replaced: refused at Hello.
  ServerFixture fx;
  TestClient old(fx.port());
  old.hello("", wire::kProtocolVersion - 1);
  const auto f = old.nextOf(Payload::Error);
  ASSERT_TRUE(f.has_value());
  const wire::Error* e = wire::envelopeOf(*f)->payload_as_Error();
  EXPECT_EQ(e->code(), ErrorCode::UnsupportedVersion);
  ASSERT_TRUE(e->text());
  EXPECT_NE(e->text()->str().find(fmt::format("protocol version {}", wire::kProtocolVersion - 1)),
            std::string::npos)
      << e->text()->str();
  EXPECT_NE(e->text()->str().find(fmt::format("speaks {}", wire::kProtocolVersion)),
            std::string::npos)
      << e->text()->str();
  EXPECT_TRUE(old.closedWithin(3.0));
  expectOthersStillServed(fx);
}

TEST(StreamServer, BadTokenGetsBadTokenAndTheRightOneGetsIn) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.token = "s3cret"; }));
  TestClient bad(fx.port());
  bad.hello("guess");
  expectRefusedAndClosed(bad, ErrorCode::BadToken);
  TestClient good(fx.port());
  good.hello("s3cret");
  EXPECT_TRUE(good.nextOf(Payload::Welcome));
}

TEST(StreamServer, MalformedFrameGetsMalformedFrameAndIsClosed) {
  ServerFixture fx;
  TestClient innocent(fx.port());
  ASSERT_TRUE(innocent.join());
  TestClient bad(fx.port());
  bad.sendRaw({8, 0, 0, 0, 0xde, 0xad, 0xbe, 0xef, 0x01, 0x02, 0x03, 0x04});
  expectRefusedAndClosed(bad, ErrorCode::MalformedFrame);
  expectServed(innocent);
}

TEST(StreamServer, OversizedFrameGetsFrameTooLargeBeforeAnyBuffering) {
  ServerFixture fx;
  TestClient bad(fx.port());
  bad.sendRaw({0xff, 0xff, 0xff, 0x7f});
  expectRefusedAndClosed(bad, ErrorCode::FrameTooLarge);
  expectOthersStillServed(fx);
}

TEST(StreamServer, OutOfOrderFramesGetOutOfOrder) {
  ServerFixture fx;
  {
    TestClient bad(fx.port());
    bad.pose({0.0, 1.7, 8.0});  // before Hello
    expectRefusedAndClosed(bad, ErrorCode::OutOfOrder);
  }
  {
    TestClient bad(fx.port());
    ASSERT_TRUE(bad.join());
    bad.sendRaw(wire::encodeMessage(wire::WelcomeT{}));  // a server message
    EXPECT_EQ(nextErrorCode(bad), ErrorCode::OutOfOrder);
  }
  {
    TestClient bad(fx.port());
    bad.hello();
    bad.hello();  // twice
    EXPECT_EQ(nextErrorCode(bad), ErrorCode::OutOfOrder);
  }
  expectOthersStillServed(fx);
}

TEST(StreamServer, NonFinitePoseGetsBadRequest) {
  ServerFixture fx;
  TestClient bad(fx.port());
  ASSERT_TRUE(bad.join());
  bad.pose({std::nan(""), 1.7, 8.0});
  expectOnlyItsSessionRefused(fx, bad, ErrorCode::BadRequest);
}

TEST(StreamServer, AClientVanishingMidFrameEndsOnlyItsSession) {
  ServerFixture fx;
  TestClient innocent(fx.port());
  ASSERT_TRUE(innocent.join());
  {
    TestClient bad(fx.port());
    ASSERT_TRUE(bad.join());
    auto frame = wire::encodeBye("x");
    frame.resize(frame.size() / 2);
    bad.sendRaw(frame);
  }  // closed with half a frame sent
  for (int i = 0; i < 50 && fx.server().sessionCount() > 1; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(fx.server().sessionCount(), 1u);
  expectServed(innocent);
}

TEST(StreamServer, SilentClientsTimeOut) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.helloTimeoutS = 0.3; }));
  TestClient silent(fx.port());
  EXPECT_EQ(nextErrorCode(silent, 3.0), ErrorCode::Timeout);
  EXPECT_TRUE(silent.closedWithin(3.0));
}

TEST(StreamServer, AClientThatStopsReadingIsClosedWhileOthersAreServed) {
  ServerFixture fx(configWith([](StreamServerConfig& c) {
    c.sendQueueLimitBytes = 64u << 10;
    c.writeStallTimeoutS = 1.0;
    c.maxFramesPerSecond = 1u << 30;
  }));
  TestClient reader(fx.port());
  ASSERT_TRUE(reader.join());
  TestClient stuck(fx.port(), 4096);
  stuck.hello();
  // Many requests, each answered with a face list; never read.
  std::vector<uint8_t> burst;
  wire::PvsRequestT req;
  req.by_cell = true;
  req.cell = std::make_unique<wire::CellIndex>(0, 0, 0);
  const auto one = wire::encodeMessage(req);
  for (int i = 0; i < 4000; ++i) burst.insert(burst.end(), one.begin(), one.end());
  boost::system::error_code ec;
  for (int round = 0; round < 20 && !ec && fx.server().sessionCount() > 1; ++round) {
    boost::asio::write(stuck.socket(), boost::asio::buffer(burst), ec);
    reader.next(0.05);
  }
  for (int i = 0; i < 100 && fx.server().sessionCount() > 1; ++i) {
    reader.next(0.05);
  }
  EXPECT_EQ(fx.server().sessionCount(), 1u) << "the session that stopped reading is still open";
  expectServed(reader);
}

TEST(StreamServer, ClientsBeyondTheMaximumGetTooManyClients) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.maxClients = 1; }));
  TestClient first(fx.port());
  ASSERT_TRUE(first.join());
  TestClient second(fx.port());
  expectRefusedAndClosed(second, ErrorCode::TooManyClients);
  expectServed(first);
}

TEST(StreamServer, AFloodOfFramesGetsRateLimited) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.maxFramesPerSecond = 50; }));
  TestClient bad(fx.port());
  ASSERT_TRUE(bad.join());
  // The server may close the session before the flood ends; the flood stops
  // at the first pose the closed connection no longer takes.
  for (int i = 0; i < 200 && bad.pose({0.0, 1.7, 8.0}); ++i) {
  }
  expectOnlyItsSessionRefused(fx, bad, ErrorCode::RateLimited);
}

TEST(StreamServer, StoppingSaysByeToEveryClient) {
  auto fx = std::make_unique<ServerFixture>();
  TestClient a(fx->port()), b(fx->port());
  a.hello();
  b.hello();
  ASSERT_TRUE(a.nextOf(Payload::Welcome));
  ASSERT_TRUE(b.nextOf(Payload::Welcome));
  fx->server().stop();
  EXPECT_TRUE(a.nextOf(Payload::Bye));
  EXPECT_TRUE(b.nextOf(Payload::Bye));
  fx.reset();
}

}  // namespace
}  // namespace vistream
