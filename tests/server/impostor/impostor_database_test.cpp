// The impostor database (server/impostor/impostor_database.h): a bake over a
// PVS database's cells gives every cell a record whose impostors decode and
// replace only faces of the cell's PVS; a bake killed midway resumes from its
// journal to the same bytes; a corrupt, foreign or mismatched file is refused
// naming what is wrong.
#include "server/impostor/impostor_database.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <map>

#include "common/scene/scene_loader.h"
#include "common/world/static_world.h"
#include "protocol/impostor/impostor_codec.h"
#include "server/impostor/view_cell_groups.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

std::string readAll(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), {});
}

struct Baked {
  TempDir dir;
  Scene scene;
  std::unique_ptr<ImpostorWorld> world;
  fs::path pvsPath;

  Baked() {
    const fs::path obj = dir.write("row.obj", testing::farRowObj());
    scene = loadScene(obj);
    const StaticWorld statics = buildStaticWorld(scene, {});
    EpsilonPvs pvs(scene);
    BakeOptions bake;
    bake.cellSize = glm::vec3(4.0f);
    bake.region = Box3f(scene.toLocal({-6.0, 0.0, -6.0}), scene.toLocal({6.0, 4.0, 6.0}));
    pvsPath = dir / "row.pvsdb";
    bakePvs(scene, pvs, statics.freeSpace, bake, pvsPath);
    world = std::make_unique<ImpostorWorld>(scene, ImpostorWorldOptions{});
  }
  static ImpostorBakeOptions options() {
    ImpostorBakeOptions o;
    o.placement.nearDistance = 100.0f;
    o.placement.minTriangles = 20;
    o.placement.maxBytesRatio = 0.0f;  // every site gets its impostor
    o.impostor.maxRays = 8;
    o.impostor.screen.width = 320;
    o.impostor.screen.height = 240;
    o.settings = "{\"test\":1}";
    o.mergeCells = 1;  // every grid cell its own view cell (merged view cells: their own test)
    return o;
  }
};

TEST(ImpostorDatabase, GivesEveryCellARecordWhoseImpostorsDecodeAndReplaceOnlyPvsFaces) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  const ImpostorBakeReport report =
      bakeImpostorDatabase(*b.world, pvs, Baked::options(), b.dir / "row.impdb");
  EXPECT_EQ(report.cells, pvs.cellCount());
  EXPECT_EQ(report.computedCells, pvs.cellCount());
  EXPECT_GT(report.impostors, 0u);
  EXPECT_FALSE(fs::exists(b.dir / "row.impdb.journal"));

  const ImpostorDatabase db = ImpostorDatabase::open(b.dir / "row.impdb");
  EXPECT_EQ(db.header().pvs.sceneFingerprint, pvs.header().sceneFingerprint);
  EXPECT_EQ(db.header().settings, "{\"test\":1}");
  EXPECT_EQ(db.cellIndices(), pvs.cellIndices());
  size_t impostors = 0;
  for (uint32_t c : db.cellIndices()) {
    const auto record = db.cell(c);
    ASSERT_TRUE(record.has_value());
    EXPECT_FALSE(record->why.empty());
    const std::vector<uint32_t> cellPvs = *pvs.cell(c);
    for (const StoredImpostor& s : record->impostors) {
      ++impostors;
      Impostor imp;
      std::string error;
      ASSERT_TRUE(wire::decodeImpostor(s.bytes, imp, error)) << error;
      EXPECT_EQ(imp.size(), s.points);
      EXPECT_FALSE(s.faces.empty());
      for (uint32_t f : s.faces)
        EXPECT_TRUE(std::binary_search(cellPvs.begin(), cellPvs.end(), f)) << f;
      // The view cell the impostor was baked for is the grid's cell.
      const Box3f box = pvs.header().grid().cellBox(pvs.header().grid().cellAt(c));
      EXPECT_EQ(imp.cell.lo, box.lo);
    }
  }
  EXPECT_EQ(impostors, report.impostors);
  // A region bakes only the cells it overlaps; the others are absent, not empty.
  const ViewCellGrid grid = pvs.header().grid();
  const std::vector<uint32_t> all = pvs.cellIndices();
  const Box3f first = grid.cellBox(grid.cellAt(all.front()));
  ImpostorBakeOptions one = Baked::options();
  one.region = Box3f(first.center() - 0.1f, first.center() + 0.1f);
  const ImpostorBakeReport partial = bakeImpostorDatabase(*b.world, pvs, one, b.dir / "one.impdb");
  EXPECT_EQ(partial.cells, 1u);
  const ImpostorDatabase oneDb = ImpostorDatabase::open(b.dir / "one.impdb");
  EXPECT_EQ(oneDb.cellIndices(), std::vector<uint32_t>{all.front()});
  EXPECT_TRUE(oneDb.cell(all.front()).has_value());
  EXPECT_FALSE(oneDb.cell(all.back()).has_value());
}

// Cells merged into view cells along a street: the leader's record holds
// the impostors baked for the whole run, every other cell's points at it;
// the impostors replace only faces of the union of the run's PVSs, each
// wholly beyond d from every cell of the run; the run's far field is whole
// (replaced or left as geometry).
TEST(ImpostorDatabase, CellsMergedIntoAViewCellShareImpostorsBakedForTheWholeRun) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  const ViewCellGrid grid = pvs.header().grid();
  ImpostorBakeOptions o = Baked::options();
  o.mergeCells = 3;
  const ImpostorBakeReport report = bakeImpostorDatabase(*b.world, pvs, o, b.dir / "m.impdb");
  EXPECT_EQ(report.cells, pvs.cellCount());
  EXPECT_EQ(report.viewCells, mergeViewCells(grid, pvs.cellIndices(), 3).size());
  ASSERT_LT(report.viewCells, report.cells);
  EXPECT_GT(report.impostors, 0u);
  const ImpostorDatabase db = ImpostorDatabase::open(b.dir / "m.impdb");
  EXPECT_EQ(db.cellIndices(), pvs.cellIndices());
  size_t merged = 0, impostors = 0;
  for (uint32_t c : db.cellIndices()) {
    const std::optional<uint32_t> leader = db.viewCellOf(c);
    ASSERT_TRUE(leader.has_value());
    const CellRecord own = *db.cell(c);
    const CellRecord view = *db.cell(*leader);
    EXPECT_EQ(own.viewLo, view.viewLo);
    EXPECT_EQ(own.viewHi, view.viewHi);
    EXPECT_EQ(*leader, grid.linearIndex(own.viewLo));
    const glm::ivec3 cell = grid.cellAt(c);
    EXPECT_TRUE(glm::all(glm::lessThanEqual(own.viewLo, cell)) &&
                glm::all(glm::lessThanEqual(cell, own.viewHi)));
    if (c != *leader) {
      ++merged;
      EXPECT_TRUE(own.impostors.empty());
      EXPECT_TRUE(own.geometryFaces.empty());
      EXPECT_NE(own.why.find(std::to_string(*leader)), std::string::npos) << own.why;
      continue;
    }
    // The union of the run's PVSs.
    std::vector<uint32_t> runPvs;
    std::vector<Box3f> runCells;
    for (int x = own.viewLo.x; x <= own.viewHi.x; ++x)
      for (int z = own.viewLo.z; z <= own.viewHi.z; ++z) {
        const glm::ivec3 m(x, own.viewLo.y, z);
        const std::vector<uint32_t> f = *pvs.cell(uint32_t(grid.linearIndex(m)));
        runPvs.insert(runPvs.end(), f.begin(), f.end());
        runCells.push_back(grid.cellBox(m));
      }
    std::sort(runPvs.begin(), runPvs.end());
    const Box3f viewBox = viewCellBox(grid, own.viewLo, own.viewHi);
    for (const StoredImpostor& s : own.impostors) {
      ++impostors;
      Impostor imp;
      std::string error;
      ASSERT_TRUE(wire::decodeImpostor(s.bytes, imp, error)) << error;
      EXPECT_EQ(imp.cell.lo, viewBox.lo);
      EXPECT_EQ(imp.cell.hi, viewBox.hi);
      for (uint32_t f : s.faces) {
        EXPECT_TRUE(std::binary_search(runPvs.begin(), runPvs.end(), f)) << f;
        // Beyond d from every cell of the run: far field for each of them.
        for (const Box3f& cellBox : runCells)
          for (uint32_t t : b.world->trianglesOfFaces({f}))
            for (int k = 0; k < 3; ++k) {
              const glm::vec3 v = b.world->triangles().vertex(t, k);
              EXPECT_GE(glm::length(v - glm::clamp(v, cellBox.lo, cellBox.hi)),
                        o.placement.nearDistance)
                  << "face " << f;
            }
      }
    }
  }
  EXPECT_GT(merged, 0u);
  EXPECT_EQ(impostors, report.impostors);
}

// The bytes rule: an impostor costing more than the ratio times the
// Geometry bytes of the faces it replaces stays geometry, and the cell says so.
TEST(ImpostorDatabase, AnImpostorCostlierThanItsGeometryByTheRatioStaysGeometry) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  const ViewCellGrid grid = pvs.header().grid();
  const uint32_t c = pvs.cellIndices().front();
  const Box3f cell = grid.cellBox(grid.cellAt(c));
  ImpostorBakeOptions o = Baked::options();
  const CellImpostors free = b.world->bakeCell(cell, *pvs.cell(c), o.placement, o.impostor);
  ASSERT_GT(free.impostors.size(), 0u);
  EXPECT_TRUE(free.refused.empty());
  EXPECT_TRUE(free.geometryFaces.empty());
  // A ratio just below each impostor's own bytes / geometry bytes refuses
  // exactly the impostors above it.
  std::vector<double> ratios;
  for (size_t i = 0; i < free.impostors.size(); ++i)
    ratios.push_back(double(free.stats[i].bytes) / double(free.geometryBytes[i]));
  std::vector<double> ascending = ratios;
  std::sort(ascending.begin(), ascending.end());
  // Just below the lower middle ratio (as a float), so that it is refused.
  float median = float(ascending[(ascending.size() - 1) / 2]);
  if (double(median) >= ascending[(ascending.size() - 1) / 2])
    median = std::nextafter(median, 0.0f);
  o.placement.maxBytesRatio = median;
  const CellImpostors capped = b.world->bakeCell(cell, *pvs.cell(c), o.placement, o.impostor);
  size_t above = 0;
  for (double r : ratios) above += r > double(median);
  ASSERT_GT(above, 0u);
  EXPECT_EQ(capped.refused.size(), above);
  EXPECT_EQ(capped.impostors.size(), free.impostors.size() - above);
  for (size_t i = 0; i < capped.impostors.size(); ++i)
    EXPECT_LE(double(capped.stats[i].bytes), median * double(capped.geometryBytes[i]) * 1.0001);
  EXPECT_NE(capped.placement.why.find("left as geometry"), std::string::npos)
      << capped.placement.why;
  EXPECT_NE(capped.refused.front().find("as geometry"), std::string::npos);
  // A ratio below every impostor's leaves the cell without impostors.
  o.placement.maxBytesRatio = 1e-6f;
  const CellImpostors none = b.world->bakeCell(cell, *pvs.cell(c), o.placement, o.impostor);
  EXPECT_TRUE(none.impostors.empty());
  EXPECT_EQ(none.refused.size(), free.impostors.size());
  // Their far field stays in the cell's record as geometry: every face an
  // impostor replaced, and only faces of the cell's PVS.
  const std::vector<uint32_t> cellPvs = *pvs.cell(c);
  for (const std::vector<uint32_t>& faces : free.replacedFaces)
    for (uint32_t f : faces)
      EXPECT_TRUE(std::binary_search(none.geometryFaces.begin(), none.geometryFaces.end(), f)) << f;
  EXPECT_TRUE(std::is_sorted(none.geometryFaces.begin(), none.geometryFaces.end()));
  for (uint32_t f : none.geometryFaces)
    EXPECT_TRUE(std::binary_search(cellPvs.begin(), cellPvs.end(), f)) << f;
  // The capped bake keeps as geometry exactly the faces of its refused sites.
  std::vector<uint32_t> keptByImpostors;
  for (const std::vector<uint32_t>& faces : capped.replacedFaces)
    keptByImpostors.insert(keptByImpostors.end(), faces.begin(), faces.end());
  for (uint32_t f : keptByImpostors)
    EXPECT_FALSE(std::binary_search(capped.geometryFaces.begin(), capped.geometryFaces.end(), f))
        << f;
  EXPECT_FALSE(capped.geometryFaces.empty());
}

// Shards (every n-th cell) joined by mergeImpostorDatabases give the bytes
// of one bake of every cell; shards of other settings are refused.
TEST(ImpostorDatabase, ShardsMergeToTheBytesOfOneBake) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  ASSERT_GE(pvs.cellCount(), 2u);
  bakeImpostorDatabase(*b.world, pvs, Baked::options(), b.dir / "all.impdb");
  std::vector<fs::path> shards;
  size_t cells = 0;
  for (uint32_t i = 0; i < 2; ++i) {
    ImpostorBakeOptions o = Baked::options();
    o.shardIndex = i;
    o.shardCount = 2;
    shards.push_back(b.dir / ("s" + std::to_string(i) + ".impdb"));
    cells += bakeImpostorDatabase(*b.world, pvs, o, shards.back()).cells;
  }
  EXPECT_EQ(cells, pvs.cellCount());
  EXPECT_LT(ImpostorDatabase::open(shards[0]).cellCount(), pvs.cellCount());
  mergeImpostorDatabases(shards, b.dir / "merged.impdb");
  EXPECT_EQ(readAll(b.dir / "merged.impdb"), readAll(b.dir / "all.impdb"));

  ImpostorBakeOptions other = Baked::options();
  other.settings = "{\"test\":2}";
  other.shardIndex = 1;
  other.shardCount = 2;
  bakeImpostorDatabase(*b.world, pvs, other, b.dir / "other.impdb");
  try {
    mergeImpostorDatabases({shards[0], b.dir / "other.impdb"}, b.dir / "bad.impdb");
    FAIL() << "shards of other settings were merged";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("other.impdb"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(b.dir / "bad.impdb"));
  ImpostorBakeOptions badShard = Baked::options();
  badShard.shardIndex = 2;
  badShard.shardCount = 2;
  EXPECT_THROW(bakeImpostorDatabase(*b.world, pvs, badShard, b.dir / "x.impdb"), InputError);
}

TEST(ImpostorDatabase, ResumesAKilledBakeFromItsJournalToTheSameBytes) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  ASSERT_GE(pvs.cellCount(), 3u);
  bakeImpostorDatabase(*b.world, pvs, Baked::options(), b.dir / "fresh.impdb");
  ImpostorBakeOptions dying = Baked::options();
  size_t calls = 0;
  dying.progress = [&](size_t, size_t) {
    if (++calls == 3) throw std::runtime_error("killed");  // after two cells
  };
  EXPECT_THROW(bakeImpostorDatabase(*b.world, pvs, dying, b.dir / "resumed.impdb"),
               std::runtime_error);
  const fs::path journal = b.dir / "resumed.impdb.journal";
  ASSERT_TRUE(fs::exists(journal));
  EXPECT_FALSE(fs::exists(b.dir / "resumed.impdb"));
  // A torn last record, as a crash mid-write leaves.
  fs::resize_file(journal, fs::file_size(journal) - 5);
  const ImpostorBakeReport report =
      bakeImpostorDatabase(*b.world, pvs, Baked::options(), b.dir / "resumed.impdb");
  EXPECT_EQ(report.resumedCells, 1u);  // the second record was torn
  EXPECT_EQ(report.computedCells, pvs.cellCount() - 1);
  EXPECT_EQ(readAll(b.dir / "fresh.impdb"), readAll(b.dir / "resumed.impdb"));
}

TEST(ImpostorDatabase, RefusesCorruptForeignAndMismatchedFilesNamingWhatIsWrong) {
  Baked b;
  const PvsDatabase pvs = PvsDatabase::open(b.pvsPath);
  const fs::path good = b.dir / "row.impdb";
  bakeImpostorDatabase(*b.world, pvs, Baked::options(), good);
  const std::string bytes = readAll(good);
  auto refusal = [&](const std::string& name, const std::string& content) {
    const fs::path p = b.dir / name;
    std::ofstream(p, std::ios::binary) << content;
    try {
      ImpostorDatabase::open(p);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("opened");
  };
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  EXPECT_NE(refusal("flipped.impdb", flipped).find("checksum mismatch"), std::string::npos);
  EXPECT_NE(refusal("cut.impdb", bytes.substr(0, bytes.size() - 9)).find("truncated"),
            std::string::npos);
  EXPECT_NE(refusal("magic.impdb", "NOTADB!!" + bytes.substr(8)).find("bad magic"),
            std::string::npos);
  // A PVS database is not an impostor database.
  EXPECT_NE(refusal("pvs.impdb", readAll(b.pvsPath)).find("not an impostor database"),
            std::string::npos);
  // View cells that do not hold together: a cell pointing at a leader that
  // is absent or of another view cell, or not holding the cell, and a
  // non-leader holding impostors.
  const ImpostorDatabase db = ImpostorDatabase::open(good);
  const ViewCellGrid grid = pvs.header().grid();
  const std::vector<uint32_t> cells = db.cellIndices();
  ASSERT_GE(cells.size(), 2u);
  auto viewRefusal = [&](const std::string& name,
                         const std::map<uint32_t, CellRecord>& records) -> std::string {
    std::map<uint32_t, std::vector<uint8_t>> encoded;
    for (const auto& [c, r] : records) encoded[c] = encodeCellRecord(r);
    writeImpostorDatabase(b.dir / name, db.header(), encoded);
    try {
      ImpostorDatabase::open(b.dir / name);
    } catch (const InputError& e) {
      return e.what();
    }
    return "opened";
  };
  const glm::ivec3 c0 = grid.cellAt(cells[0]), c1 = grid.cellAt(cells[1]);
  CellRecord leaderless;
  leaderless.viewLo = c0;
  leaderless.viewHi = glm::max(c0, c1);
  EXPECT_NE(viewRefusal("leaderless.impdb", {{cells[1], leaderless}}).find("missing"),
            std::string::npos);
  CellRecord elsewhere;
  elsewhere.viewLo = elsewhere.viewHi = c1;
  EXPECT_NE(viewRefusal("elsewhere.impdb", {{cells[0], elsewhere}}).find("does not hold it"),
            std::string::npos);
  CellRecord alone;
  alone.viewLo = alone.viewHi = c0;
  EXPECT_NE(viewRefusal("other.impdb", {{cells[0], alone}, {cells[1], leaderless}})
                .find("of another view cell"),
            std::string::npos);
  CellRecord leader = leaderless, member = leaderless;
  member.geometryFaces = {1};
  EXPECT_NE(viewRefusal("member.impdb", {{cells[0], leader}, {cells[1], member}})
                .find("leader is another cell"),
            std::string::npos);
  EXPECT_EQ(viewRefusal("fine.impdb", {{cells[0], leader}, {cells[1], leaderless}}), "opened");
  // Baking against another scene's PVS database is refused.
  testing::GroundAndBoxesObj other(-50, -50, 50, 50);
  other.box("lonely", 0, -30, 4, -26, 5);
  const fs::path otherObj = b.dir.write("other.obj", other.obj);
  const Scene otherScene = loadScene(otherObj);
  const ImpostorWorld otherWorld(otherScene, {});
  try {
    bakeImpostorDatabase(otherWorld, pvs, Baked::options(), b.dir / "other.impdb");
    ADD_FAILURE() << "baked against another scene's PVS database";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not for this scene"), std::string::npos) << e.what();
  }
}

TEST(ImpostorDatabase, CellRecordsRefuseCutAndOutOfRangeBytes) {
  CellRecord record;
  record.why = "1 impostor";
  StoredImpostor s;
  s.sector = 3;
  s.faces = {4, 9, 17};
  s.bytes = {1, 2, 3, 4, 5};
  s.points = 40;
  record.impostors.push_back(s);
  record.geometryFaces = {2, 30};
  record.viewLo = {1, 0, 2};
  record.viewHi = {1, 0, 5};
  const std::vector<uint8_t> bytes = encodeCellRecord(record);
  const CellRecord back = decodeCellRecord(bytes, 100);
  ASSERT_EQ(back.impostors.size(), 1u);
  EXPECT_EQ(back.why, record.why);
  EXPECT_EQ(back.impostors[0].faces, s.faces);
  EXPECT_EQ(back.impostors[0].bytes, s.bytes);
  EXPECT_EQ(back.impostors[0].points, 40u);
  EXPECT_EQ(back.geometryFaces, record.geometryFaces);
  EXPECT_EQ(back.viewLo, record.viewLo);
  EXPECT_EQ(back.viewHi, record.viewHi);
  for (size_t n = 0; n < bytes.size(); ++n)
    EXPECT_THROW(decodeCellRecord(std::span(bytes.data(), n), 100), InputError) << n;
  EXPECT_THROW(decodeCellRecord(bytes, 10), InputError);  // face 17 is beyond the scene
  EXPECT_THROW(decodeCellRecord(bytes, 20), InputError);  // geometry face 30 is beyond it
}

}  // namespace
}  // namespace vistream
