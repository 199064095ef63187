// Impostors over the wire (server/stream/session.h, --impostor-db): a client
// whose Hello asks for impostors gets those of its cell, as the impostor
// database holds them, and none of the faces they replace as geometry; a
// client that does not ask gets those faces and no impostor. A site left as
// geometry (its impostor would cost more bytes) reaches a client that asks
// as faces, even beyond its near-field radius. Cells merged into one view
// cell are sent its impostors once. Oracle: the impostor
// database's own record of the cell, and the row's known distance.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "common/scene/scene_loader.h"
#include "common/world/static_world.h"
#include "protocol/impostor/impostor_codec.h"
#include "protocol/impostor/impostor_message.h"
#include "server/impostor/impostor_database.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/temp_dir.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream {
namespace {

namespace fs = std::filesystem;
using testing::ServerFixture;
using testing::TestClient;
using wire::Payload;

// A row of boxes 120-170 m north of the origin, its cells' impostors baked
// with `maxBytesRatio` (0: every site gets its impostor), cells merged into
// view cells of up to `mergeCells`.
struct BakedRow {
  testing::TempDir dir;
  fs::path obj, pvs, impostors;
  explicit BakedRow(float maxBytesRatio = 0.0f,
                    uint32_t mergeCells = ImpostorBakeOptions{}.mergeCells) {
    obj = dir.write("row.obj", testing::farRowObj());
    const Scene scene = loadScene(obj);
    BakeOptions bake;
    bake.cellSize = glm::vec3(4.0f);
    bake.region = Box3f(scene.toLocal({-6.0, 0.0, -6.0}), scene.toLocal({6.0, 4.0, 6.0}));
    pvs = dir / "row.pvsdb";
    bakePvs(scene, EpsilonPvs(scene), buildStaticWorld(scene, {}).freeSpace, bake, pvs);
    ImpostorBakeOptions o;
    o.placement.nearDistance = 100.0f;
    o.placement.minTriangles = 20;
    o.placement.maxBytesRatio = maxBytesRatio;
    o.mergeCells = mergeCells;
    o.impostor.maxRays = 8;
    o.impostor.screen.width = 320;
    o.impostor.screen.height = 240;
    impostors = dir / "row.impdb";
    bakeImpostorDatabase(ImpostorWorld(scene, ImpostorWorldOptions{}), PvsDatabase::open(pvs), o,
                         impostors);
  }
};

// A server of the row with both databases, and the impostor record of the
// view cell holding the cell the clients stand in (at the origin), named by
// its leader (`view`; the cell itself unless cells were merged).
struct RowServer {
  ServerFixture fx;
  glm::ivec3 cell{0}, view{0};
  std::optional<CellRecord> record;
  explicit RowServer(const BakedRow& b) : fx({}, loadScene(b.obj), options(b)) {
    cell = *fx.world().cellOf(glm::vec3(0.5f, 2.0f, 0.5f) - glm::vec3(fx.world().scene().origin));
    const ImpostorDatabase db = ImpostorDatabase::open(b.impostors);
    const uint32_t leader = *db.viewCellOf(uint32_t(fx.world().grid().linearIndex(cell)));
    view = fx.world().grid().cellAt(leader);
    record = db.cell(leader);
  }
  static StreamWorldOptions options(const BakedRow& b) {
    StreamWorldOptions wo;
    wo.pvsDatabase = b.pvs;
    wo.impostorDatabase = b.impostors;
    return wo;
  }
};

struct ImpostorsReceived {
  bool offered = false;
  std::set<uint32_t> geometryFaces;
  std::vector<wire::ImpostorMessage> impostors;  // in the order received
};

// Joins (by default with radius 400 m: every face of the row is within it),
// stands at each place in turn (by default the origin) and reads until the
// server has nothing more to send for 1.5 s.
ImpostorsReceived walkIn(uint16_t port, bool wantsImpostors, float radius = 400.0f,
                         const std::vector<glm::dvec3>& places = {{0.5, 2.0, 0.5}}) {
  TestClient c(port);
  wire::HelloT h;
  h.protocol_version = wire::kProtocolVersion;
  h.capabilities = std::make_unique<wire::CapabilitiesT>();
  h.capabilities->near_field_radius_m = radius;
  h.capabilities->wants_impostors = wantsImpostors;
  h.capabilities->wants_avatars = false;
  c.sendRaw(wire::encodeMessage(std::move(h)));
  ImpostorsReceived r;
  const auto welcome = c.nextOf(Payload::Welcome);
  EXPECT_TRUE(welcome);
  if (!welcome) return r;
  const wire::Welcome* w = wire::envelopeOf(*welcome)->payload_as_Welcome();
  r.offered = w->impostors();
  const wire::QuantizationGrid grid{wire::fromWire(*w->quant_origin()), w->quant_step()};
  for (const glm::dvec3& place : places) {
    c.pose(place);
    while (const auto f = c.next(1.5)) {
      const wire::Envelope* e = wire::envelopeOf(*f);
      if (e->payload_type() == Payload::Geometry) {
        wire::DecodedGeometry g;
        std::string error;
        EXPECT_TRUE(wire::decodeGeometry(*e->payload_as_Geometry(), grid, g, error)) << error;
        r.geometryFaces.insert(g.faces.begin(), g.faces.end());
      } else if (e->payload_type() == Payload::ImpostorData) {
        wire::ImpostorMessage m;
        std::string error;
        EXPECT_TRUE(readImpostorMessage(*e->payload_as_ImpostorData(), w->face_count(), m, error))
            << error;
        r.impostors.push_back(std::move(m));
      }
    }
  }
  return r;
}

TEST(ImpostorStream, AClientThatAsksGetsItsCellsImpostorsAndNotTheFacesTheyReplace) {
  const BakedRow b;
  RowServer server(b);
  ServerFixture& fx = server.fx;
  const glm::ivec3 view = server.view;
  const auto& record = server.record;
  ASSERT_TRUE(record);
  ASSERT_FALSE(record->impostors.empty()) << record->why;
  std::set<uint32_t> replaced;
  for (const StoredImpostor& s : record->impostors) replaced.insert(s.faces.begin(), s.faces.end());

  const ImpostorsReceived with = walkIn(fx.port(), true);
  EXPECT_TRUE(with.offered);
  // The current cell's impostors, in order, byte for byte as stored.
  std::vector<const wire::ImpostorMessage*> ofCell;
  for (const auto& m : with.impostors)
    if (m.cell == view) ofCell.push_back(&m);
  ASSERT_EQ(ofCell.size(), record->impostors.size());
  for (size_t i = 0; i < ofCell.size(); ++i) {
    EXPECT_EQ(ofCell[i]->index, i);
    EXPECT_EQ(ofCell[i]->count, record->impostors.size());
    EXPECT_EQ(ofCell[i]->replacedFaces, record->impostors[i].faces);
    EXPECT_EQ(ofCell[i]->data, record->impostors[i].bytes);
    Impostor decoded;
    std::string error;
    EXPECT_TRUE(wire::decodeImpostor(ofCell[i]->data, decoded, error)) << error;
  }
  EXPECT_EQ(ofCell.front()->why, record->why);
  EXPECT_FALSE(with.geometryFaces.empty());
  for (const uint32_t f : replaced) EXPECT_FALSE(with.geometryFaces.count(f)) << "face " << f;

  const ImpostorsReceived without = walkIn(fx.port(), false);
  EXPECT_FALSE(without.offered);
  EXPECT_TRUE(without.impostors.empty());
  for (const uint32_t f : replaced) EXPECT_TRUE(without.geometryFaces.count(f)) << "face " << f;
}

TEST(ImpostorStream, ASiteLeftAsGeometryIsSentAsFacesBeyondTheClientsRadius) {
  // A ratio no impostor meets: every site of the row stays geometry.
  const BakedRow b(1e-6f);
  RowServer server(b);
  ServerFixture& fx = server.fx;
  const glm::ivec3 view = server.view;
  const auto& record = server.record;
  ASSERT_TRUE(record);
  EXPECT_TRUE(record->impostors.empty());
  ASSERT_FALSE(record->geometryFaces.empty()) << record->why;

  // The row lies 120 m or more from the client, beyond a radius of 50 m.
  const ImpostorsReceived with = walkIn(fx.port(), true, 50.0f);
  for (const uint32_t f : record->geometryFaces)
    EXPECT_TRUE(with.geometryFaces.count(f)) << "face " << f;
  for (const auto& m : with.impostors) {
    if (m.cell == view) {
      EXPECT_EQ(m.count, 0u);
    }
  }
  // Without impostors the radius rules: none of them is sent.
  const ImpostorsReceived without = walkIn(fx.port(), false, 50.0f);
  for (const uint32_t f : record->geometryFaces)
    EXPECT_FALSE(without.geometryFaces.count(f)) << "face " << f;
}

// Cells merged into one view cell along the row's street: a client walking
// from one of its cells to the next is sent the view cell's impostors once,
// named by its first and last cells, and the faces they replace in neither.
TEST(ImpostorStream, AWalkAcrossOneViewCellIsSentItsImpostorsOnce) {
  const BakedRow b(0.0f, 3);
  RowServer server(b);
  const auto& record = server.record;
  ASSERT_TRUE(record);
  ASSERT_FALSE(record->impostors.empty()) << record->why;
  ASSERT_NE(record->viewLo, record->viewHi) << "the cells were not merged";
  // Two places in the view cell, in different grid cells.
  const ViewCellGrid& grid = server.fx.world().grid();
  const glm::dvec3 origin = server.fx.world().scene().origin;
  const glm::dvec3 first = origin + glm::dvec3(grid.cellBox(record->viewLo).center());
  const glm::dvec3 last = origin + glm::dvec3(grid.cellBox(record->viewHi).center());
  const ImpostorsReceived with = walkIn(server.fx.port(), true, 400.0f, {first, last});
  std::vector<const wire::ImpostorMessage*> ofView;
  for (const auto& m : with.impostors)
    if (m.cell == record->viewLo) ofView.push_back(&m);
  ASSERT_EQ(ofView.size(), record->impostors.size());
  for (size_t i = 0; i < ofView.size(); ++i) {
    EXPECT_EQ(ofView[i]->index, i);
    EXPECT_EQ(ofView[i]->last(), record->viewHi);
    EXPECT_EQ(ofView[i]->data, record->impostors[i].bytes);
  }
  // No other message names a cell inside the view cell.
  for (const auto& m : with.impostors) {
    if (m.cell != record->viewLo) {
      EXPECT_FALSE(glm::all(glm::lessThanEqual(record->viewLo, m.cell)) &&
                   glm::all(glm::lessThanEqual(m.cell, record->viewHi)));
    }
  }
  for (const StoredImpostor& s : record->impostors)
    for (const uint32_t f : s.faces) EXPECT_FALSE(with.geometryFaces.count(f)) << "face " << f;
}

TEST(ImpostorStream, AnImpostorDatabaseWithoutItsPvsDatabaseIsRefused) {
  const BakedRow b;
  StreamWorldOptions wo;
  wo.impostorDatabase = b.impostors;
  try {
    StreamWorld w(loadScene(b.obj), wo);
    ADD_FAILURE() << "an impostor database without --pvs-db was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("needs --pvs-db"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace vistream
