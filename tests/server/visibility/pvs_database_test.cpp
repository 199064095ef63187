#include "server/visibility/pvs_database.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/core/error.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using testing::TempDir;

std::string errorOf(const std::function<void()>& f) { return testing::inputErrorOf(f); }

TEST(FaceList, RoundTripsSortedIdsOfEveryMagnitude) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<uint32_t> faces;
    uint32_t f = trial % 3 == 0 ? 0u : rng() % 100;
    for (int i = 0; i < 200; ++i) {
      faces.push_back(f);
      const uint32_t step = 1 + rng() % (i % 7 == 0 ? 5'000'000u : 40u);
      if (f > 0xffffffffu - step) break;
      f += step;
    }
    const auto bytes = encodeFaceList(faces);
    EXPECT_EQ(decodeFaceList(bytes.data(), bytes.size(), uint32_t(faces.size())), faces);
  }
  const std::vector<uint32_t> top = {0xfffffffeu, 0xffffffffu};
  const auto bytes = encodeFaceList(top);
  EXPECT_EQ(decodeFaceList(bytes.data(), bytes.size(), 2), top);
}

TEST(FaceList, RejectsTruncatedRepeatedAndMiscountedLists) {
  const std::vector<uint8_t> truncated = {0x85};  // continuation bit, then nothing
  EXPECT_THAT(errorOf([&] { decodeFaceList(truncated.data(), truncated.size(), 1); }), HasSubstr("malformed varint"));
  const std::vector<uint8_t> repeated = {5, 0};   // delta 0 after the first
  EXPECT_THAT(errorOf([&] { decodeFaceList(repeated.data(), repeated.size(), 2); }), HasSubstr("strictly increasing"));
  const std::vector<uint8_t> two = {5, 1};
  EXPECT_THAT(errorOf([&] { decodeFaceList(two.data(), two.size(), 1); }), HasSubstr("header says 1"));
  const std::vector<uint8_t> huge = {0xff, 0xff, 0xff, 0xff, 0x7f};  // > 32 bits
  EXPECT_THAT(errorOf([&] { decodeFaceList(huge.data(), huge.size(), 1); }), HasSubstr("face list"));
}

PvsDatabaseHeader smallHeader() {
  PvsDatabaseHeader h;
  h.sceneName = "unit";
  h.sceneFingerprint = 42;
  h.sceneFaces = 1000;
  h.origin = {50000.0, 0.0, -50000.0};
  h.gridLo = {-10.0f, 0.2f, -10.0f};
  h.cellSize = {4.0f, 2.0f, 4.0f};
  h.dims = {5, 1, 5};
  return h;
}

TEST(PvsDatabase, ReadsBackWhatWasWrittenAndLeavesNoTemporaryFile) {
  TempDir dir;
  const std::map<uint32_t, std::vector<uint32_t>> cells = {{0, {1, 2, 3}}, {7, {}}, {24, {0, 999}}};
  writePvsDatabase(dir / "a.db", smallHeader(), cells);
  EXPECT_FALSE(fs::exists(dir / "a.db.tmp"));
  const PvsDatabase db = PvsDatabase::open(dir / "a.db");
  EXPECT_EQ(db.cellCount(), 3u);
  EXPECT_EQ(db.cellIndices(), (std::vector<uint32_t>{0, 7, 24}));
  EXPECT_EQ(*db.cell(0), (std::vector<uint32_t>{1, 2, 3}));
  EXPECT_EQ(*db.cell(7), std::vector<uint32_t>{});
  EXPECT_EQ(*db.cell(24), (std::vector<uint32_t>{0, 999}));
  EXPECT_FALSE(db.cell(3).has_value());
  EXPECT_TRUE(db.header().compatible(smallHeader()));
  EXPECT_EQ(db.header().origin, smallHeader().origin);
  EXPECT_EQ(db.header().grid().dims(), glm::ivec3(5, 1, 5));
}

TEST(PvsDatabase, RejectsCorruptTruncatedAndForeignFilesNamingTheFile) {
  TempDir dir;
  writePvsDatabase(dir / "good.db", smallHeader(), {{0, {1, 2, 3}}, {5, {4, 5}}});
  std::ifstream in(dir / "good.db", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  auto variant = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir / name, std::ios::binary) << content;
    return errorOf([&] { PvsDatabase::open(dir / name); });
  };
  std::string flipped = bytes;
  flipped[bytes.size() - 9] ^= 0x10;
  EXPECT_THAT(variant("flipped.db", flipped), HasSubstr("checksum mismatch"));
  EXPECT_THAT(variant("short.db", bytes.substr(0, bytes.size() - 5)), HasSubstr("truncated"));
  EXPECT_THAT(variant("magic.db", "NOTADB!!" + bytes.substr(8)), HasSubstr("bad magic"));
  std::string version = bytes;
  version[8] = 9;
  EXPECT_THAT(variant("version.db", version), HasSubstr("version 9"));
  EXPECT_THAT(variant("empty.db", ""), HasSubstr("only 0 bytes"));
  EXPECT_THAT(errorOf([&] { PvsDatabase::open(dir / "missing.db"); }), HasSubstr("missing.db"));
  EXPECT_THAT(errorOf([&] { PvsDatabase::open(fs::temp_directory_path()); }), HasSubstr("not a regular file"));
}

// A town of 3 x 3 buildings with streets, for bakes.
struct Town {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  FreeSpace freeSpace;
  std::unique_ptr<EpsilonPvs> pvs;
  Town() {
    scene.name = "town";
    testing::addGround(scene, -30, -30, 30, 30);
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k)
        testing::addBox(scene, "b", {-26.0f + 18.0f * float(i), 0.0f, -26.0f + 18.0f * float(k)},
                        {-16.0f + 18.0f * float(i), 8.0f + 3.0f * float(i), -16.0f + 18.0f * float(k)});
    finalizeScene(scene);
    triangles = flattenScene(scene, true);
    rays = makeEmbreeRayQuery(triangles);
    freeSpace = FreeSpace::build(*rays, scene.bounds());
    pvs = std::make_unique<EpsilonPvs>(scene);
  }
};

const Town& town() {
  static const Town t;
  return t;
}

BakeOptions townBake() {
  BakeOptions o;
  o.cellSize = {4.0f, 2.0f, 4.0f};
  o.threads = 2;
  return o;
}

TEST(PvsBake, CoversTheStreetsButNotTheInsideOfBuildings) {
  const ViewCellGrid grid = bakeGrid(town().scene, town().freeSpace, townBake());
  const auto cells = freeSpaceCells(town().scene, grid, town().freeSpace);
  ASSERT_FALSE(cells.empty());
  EXPECT_LT(cells.size(), grid.cellCount());
  for (uint32_t c : cells) {
    const Box3f b = grid.cellBox(grid.cellAt(c));
    // No baked cell lies entirely inside a building footprint.
    const glm::vec2 lo(b.lo.x, b.lo.z), hi(b.hi.x, b.hi.z);
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) {
        const glm::vec2 blo(-26.0f + 18.0f * float(i), -26.0f + 18.0f * float(k)), bhi = blo + glm::vec2(10.0f);
        EXPECT_FALSE(lo.x >= blo.x && hi.x <= bhi.x && lo.y >= blo.y && hi.y <= bhi.y) << "cell " << c;
      }
  }
}

TEST(PvsBake, StoresForEveryCellThePvsOfItsBox) {
  TempDir dir;
  BakeOptions options = townBake();
  options.coarseToFine = false;
  const BakeReport report = bakePvs(town().scene, *town().pvs, town().freeSpace, options, dir / "t.db");
  EXPECT_EQ(report.computedCells, report.freeCells);
  EXPECT_FALSE(fs::exists(dir / "t.db.journal"));
  const PvsDatabase db = PvsDatabase::open(dir / "t.db");
  EXPECT_EQ(db.cellCount(), report.freeCells);
  EXPECT_EQ(db.header().sceneFingerprint, sceneFingerprint(town().scene));
  const ViewCellGrid grid = db.header().grid();
  for (uint32_t c : db.cellIndices())
    EXPECT_EQ(*db.cell(c), town().pvs->compute(grid.cellBox(grid.cellAt(c))).faces) << "cell " << c;
}

TEST(PvsBake, CoarseToFineKeepsEveryCellConservativeAndNoLarger) {
  TempDir dir;
  BakeOptions fine = townBake();
  fine.coarseToFine = false;
  bakePvs(town().scene, *town().pvs, town().freeSpace, fine, dir / "fine.db");
  bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "c2f.db");
  const PvsDatabase a = PvsDatabase::open(dir / "fine.db"), b = PvsDatabase::open(dir / "c2f.db");
  ASSERT_EQ(a.cellIndices(), b.cellIndices());
  const ViewCellGrid grid = a.header().grid();
  for (uint32_t c : a.cellIndices()) {
    const auto fa = *a.cell(c), fb = *b.cell(c);
    EXPECT_TRUE(std::includes(fa.begin(), fa.end(), fb.begin(), fb.end())) << "cell " << c;
    SampledVisibilityOptions gt;
    gt.points = 12;
    gt.resolution = 48;
    for (uint32_t f : sampleVisibleFaces(*town().rays, town().triangles, grid.cellBox(grid.cellAt(c)), gt).faces)
      EXPECT_TRUE(std::binary_search(fb.begin(), fb.end(), f)) << "cell " << c << " misses face " << f;
  }
}

TEST(PvsBake, ResumesFromAJournalWithATornTailAndGivesTheSameDatabase) {
  TempDir dir;
  bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "fresh.db");
  // A first run that dies: cut its progress callback short by throwing, then
  // tear the journal's last record as a crash mid-write would.
  BakeOptions dying = townBake();
  dying.threads = 1;
  size_t calls = 0;
  dying.progress = [&](size_t, size_t) {
    if (++calls == 6) throw std::runtime_error("killed");
  };
  EXPECT_THROW(bakePvs(town().scene, *town().pvs, town().freeSpace, dying, dir / "resumed.db"), std::runtime_error);
  const fs::path journal = dir / "resumed.db.journal";
  ASSERT_TRUE(fs::exists(journal));
  EXPECT_FALSE(fs::exists(dir / "resumed.db"));
  fs::resize_file(journal, fs::file_size(journal) - 3);
  const BakeReport report = bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "resumed.db");
  EXPECT_GT(report.resumedCells, 0u);
  EXPECT_LT(report.computedCells, report.freeCells);
  std::ifstream a(dir / "fresh.db", std::ios::binary), b(dir / "resumed.db", std::ios::binary);
  const std::string ba((std::istreambuf_iterator<char>(a)), {}), bb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(ba, bb);
}

TEST(PvsBake, IgnoresAJournalFromOtherParameters) {
  TempDir dir;
  BakeOptions other = townBake();
  other.cellSize = {5.0f, 2.0f, 5.0f};
  size_t calls = 0;
  other.threads = 1;
  other.progress = [&](size_t, size_t) {
    if (++calls == 4) throw std::runtime_error("killed");
  };
  EXPECT_THROW(bakePvs(town().scene, *town().pvs, town().freeSpace, other, dir / "x.db"), std::runtime_error);
  const BakeReport report = bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "x.db");
  EXPECT_EQ(report.resumedCells, 0u);
  EXPECT_EQ(report.computedCells, report.freeCells);
}

TEST(PvsBake, ShardsMergeIntoTheWholeBakeAndMismatchedDatabasesAreRefused) {
  TempDir dir;
  bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "all.db");
  size_t shardCells = 0;
  for (uint32_t i = 0; i < 3; ++i) {
    BakeOptions o = townBake();
    o.shardIndex = i;
    o.shardCount = 3;
    shardCells += bakePvs(town().scene, *town().pvs, town().freeSpace, o, dir / ("s" + std::to_string(i) + ".db")).shardCells;
  }
  mergePvsDatabases({dir / "s0.db", dir / "s1.db", dir / "s2.db"}, dir / "merged.db");
  const PvsDatabase all = PvsDatabase::open(dir / "all.db"), merged = PvsDatabase::open(dir / "merged.db");
  EXPECT_EQ(shardCells, all.cellCount());
  ASSERT_EQ(merged.cellIndices(), all.cellIndices());
  for (uint32_t c : all.cellIndices()) EXPECT_EQ(*merged.cell(c), *all.cell(c));

  BakeOptions coarse = townBake();
  coarse.cellSize = {8.0f, 2.0f, 8.0f};
  bakePvs(town().scene, *town().pvs, town().freeSpace, coarse, dir / "coarse.db");
  EXPECT_THAT(errorOf([&] { mergePvsDatabases({dir / "all.db", dir / "coarse.db"}, dir / "bad.db"); }),
              HasSubstr("coarse.db"));
  EXPECT_FALSE(fs::exists(dir / "bad.db"));
  BakeOptions badShard = townBake();
  badShard.shardIndex = 3;
  badShard.shardCount = 3;
  EXPECT_THAT(errorOf([&] { bakePvs(town().scene, *town().pvs, town().freeSpace, badShard, dir / "z.db"); }),
              HasSubstr("shard 3/3"));
}

}  // namespace
}  // namespace vistream
