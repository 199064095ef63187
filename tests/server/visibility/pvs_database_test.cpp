#include "server/visibility/pvs_database.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <string_view>

#include "common/core/error.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/captured_log.h"
#include "tests/common/support/pvs_truth.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using testing::CapturedLog;
using testing::TempDir;

std::string errorOf(const std::function<void()>& f) {
  return testing::inputErrorOf(f);
}

std::string readBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

void writeBytes(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

// FNV-1a 64 written out from its definition (Fowler, Noll and Vo: offset
// basis 0xcbf29ce484222325 = 14695981039346656037, prime 0x100000001b3),
// independent of the code under test.
constexpr uint64_t kReferenceFnvBasis = 0xcbf29ce484222325ull;
uint64_t referenceFnv1a64(std::string_view bytes, uint64_t h = kReferenceFnvBasis) {
  for (const char c : bytes) {
    h ^= uint8_t(c);
    h *= 0x100000001b3ull;
  }
  return h;
}

uint64_t getLe64(const std::string& b, size_t at) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= uint64_t(uint8_t(b[at + size_t(i)])) << (8 * i);
  return v;
}
void putLe64(std::string& b, size_t at, uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + size_t(i)] = char(uint8_t(v >> (8 * i)));
}

// Seals an edited database again: the header's checksum (bytes 24..31) over
// the payload (bytes 32..), so only the edit itself is wrong.
void resealChecksum(std::string& db, uint64_t basis = kReferenceFnvBasis) {
  putLe64(db, 24, referenceFnv1a64(std::string_view(db).substr(32), basis));
}

std::string asString(const std::vector<uint8_t>& v) {
  return std::string(v.begin(), v.end());
}

// Replaces the one occurrence of `from` in `bytes` by `to`, of the same length.
void replaceOnce(std::string& bytes, const std::string& from, const std::string& to) {
  ASSERT_EQ(from.size(), to.size());
  const size_t at = bytes.find(from);
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(bytes.find(from, at + 1), std::string::npos)
      << "the pattern must be unique in the file";
  bytes.replace(at, from.size(), to);
}

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
  EXPECT_THAT(errorOf([&] { decodeFaceList(truncated.data(), truncated.size(), 1); }),
              HasSubstr("malformed varint"));
  const std::vector<uint8_t> repeated = {5, 0};  // delta 0 after the first
  EXPECT_THAT(errorOf([&] { decodeFaceList(repeated.data(), repeated.size(), 2); }),
              HasSubstr("strictly increasing"));
  const std::vector<uint8_t> two = {5, 1};
  EXPECT_THAT(errorOf([&] { decodeFaceList(two.data(), two.size(), 1); }),
              HasSubstr("header says 1"));
  const std::vector<uint8_t> huge = {0xff, 0xff, 0xff, 0xff, 0x7f};  // > 32 bits
  EXPECT_THAT(errorOf([&] { decodeFaceList(huge.data(), huge.size(), 1); }),
              HasSubstr("face list"));
}

TEST(FaceList, RejectsFacesAtOrBeyondTheFaceLimit) {
  const auto bytes = encodeFaceList({3, 9});
  EXPECT_EQ(decodeFaceList(bytes.data(), bytes.size(), 2, 10), (std::vector<uint32_t>{3, 9}));
  EXPECT_THAT(errorOf([&] { decodeFaceList(bytes.data(), bytes.size(), 2, 9); }),
              HasSubstr("entry 1 is face 9, not below the face count 9"));
}

TEST(Fnv1a64, MatchesThePublishedTestVectors) {
  EXPECT_EQ(kFnv1a64OffsetBasis, 14695981039346656037ull);
  EXPECT_EQ(fnv1a64("", 0), 0xcbf29ce484222325ull);
  EXPECT_EQ(fnv1a64("a", 1), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(fnv1a64("foobar", 6), 0x85944171f73967e8ull);
  // In pieces, as the scene fingerprint hashes its fields.
  EXPECT_EQ(fnv1a64("bar", 3, fnv1a64("foo", 3)), 0x85944171f73967e8ull);
  // The reference used below agrees with the same vectors.
  EXPECT_EQ(referenceFnv1a64(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(referenceFnv1a64("a"), 0xaf63dc4c8601ec8cull);
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
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"a.db"});
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
  EXPECT_THAT(errorOf([&] { PvsDatabase::open(fs::temp_directory_path()); }),
              HasSubstr("not a regular file"));
}

TEST(PvsDatabase, ChecksumIsFnv1a64OfThePayload) {
  TempDir dir;
  writePvsDatabase(dir / "a.db", smallHeader(), {{0, {1, 2, 3}}, {5, {4, 5}}});
  const std::string bytes = readBytes(dir / "a.db");
  ASSERT_GT(bytes.size(), 32u);
  EXPECT_EQ(getLe64(bytes, 24), referenceFnv1a64(std::string_view(bytes).substr(32)));
}

TEST(PvsDatabase, RefusesAVersion1FileNamingTheFileAndBothVersionsAndSayingToRebake) {
  TempDir dir;
  writePvsDatabase(dir / "a.db", smallHeader(), {{0, {1, 2, 3}}});
  // What version 1 wrote: the same payload, checksummed from the wrong basis.
  std::string v1 = readBytes(dir / "a.db");
  v1[8] = 1;
  resealChecksum(v1, 1469598103934665603ull);
  writeBytes(dir / "old.db", v1);
  const std::string error = errorOf([&] { PvsDatabase::open(dir / "old.db"); });
  EXPECT_THAT(error, HasSubstr("old.db"));
  EXPECT_THAT(error, HasSubstr("version 1 is not supported"));
  EXPECT_THAT(error, HasSubstr("this build reads version 2"));
  EXPECT_THAT(error, HasSubstr("re-bake"));
}

TEST(PvsDatabase, OpensADatabaseOfMoreThanAMillionCells) {
  // One FlatBuffers table per cell: the verifier's default cap of 10^6 tables
  // used to refuse such a file as corrupt.
  PvsDatabaseHeader h = smallHeader();
  h.dims = {1024, 1, 1000};
  std::map<uint32_t, std::vector<uint32_t>> cells;
  for (uint32_t c = 0; c < 1024u * 1000u; ++c)
    cells.emplace_hint(cells.end(), c, std::vector<uint32_t>{});
  cells[777'777] = {5, 6, 999};
  TempDir dir;
  writePvsDatabase(dir / "big.db", h, cells);
  const PvsDatabase db = PvsDatabase::open(dir / "big.db");
  EXPECT_EQ(db.cellCount(), 1'024'000u);
  EXPECT_EQ(*db.cell(777'777), (std::vector<uint32_t>{5, 6, 999}));
}

// The report's scene: city1 has 21,280 faces, IDs 0 to 21,279.
PvsDatabaseHeader cityHeader() {
  PvsDatabaseHeader h = smallHeader();
  h.sceneFaces = 21280;
  return h;
}

// Cell 7 is i,j,k 2,0,1 of the 5 x 1 x 5 grid.
const std::vector<uint32_t> kCell7 = {100, 200, 21279};

// Writes a good database, replaces cell 7's face bytes by `edited` (same
// length) and recomputes the checksum, so only the face list is wrong;
// returns the message of open()'s InputError.
std::string openErrorWithCell7Bytes(const TempDir& dir, const std::string& name,
                                    const std::string& edited) {
  writePvsDatabase(dir / "good.db", cityHeader(), {{0, {1, 2, 3}}, {7, kCell7}, {24, {0, 21279}}});
  std::string bytes = readBytes(dir / "good.db");
  replaceOnce(bytes, asString(encodeFaceList(kCell7)), edited);
  resealChecksum(bytes);
  writeBytes(dir / name, bytes);
  return errorOf([&] { PvsDatabase::open(dir / name); });
}

// Expects open() to refuse the database whose cell 7 has the bytes `edited`,
// saved as `name`, with a message naming the file, the cell with its grid
// index, and `what`.
void expectCell7Refused(const std::string& name, const std::string& edited,
                        const std::string& what) {
  TempDir dir;
  const std::string error = openErrorWithCell7Bytes(dir, name, edited);
  EXPECT_THAT(error, HasSubstr(name));
  EXPECT_THAT(error, HasSubstr("cell 7 (i,j,k 2,0,1)"));
  EXPECT_THAT(error, HasSubstr(what));
}

TEST(PvsDatabase, OpensTheUneditedCityDatabaseItsCorruptVariantsStartFrom) {
  TempDir dir;
  EXPECT_EQ(openErrorWithCell7Bytes(dir, "same.db", asString(encodeFaceList(kCell7))),
            "<no InputError thrown>");
  EXPECT_EQ(*PvsDatabase::open(dir / "same.db").cell(7), kCell7);
}

TEST(PvsDatabase, RefusesAtOpenACellListThatIsNotStrictlyIncreasingNamingTheFileAndCell) {
  // 100, 100, 21179: a zero delta, in as many bytes as the good list.
  expectCell7Refused("repeated.db", asString(encodeFaceList({100, 100, 21179})),
                     "not strictly increasing at entry 1");
}

TEST(PvsDatabase, RefusesAtOpenACellListingAFaceIdEqualToTheFaceCountNamingTheFileAndCell) {
  expectCell7Refused("beyond.db", asString(encodeFaceList({100, 200, 21280})),
                     "entry 2 is face 21280, not below the face count 21280");
}

TEST(PvsDatabase, RefusesAtOpenACellListEndingInsideAVarintNamingTheFileAndCell) {
  std::string cut = asString(encodeFaceList(kCell7));
  cut.back() = char(0x81);  // a continuation bit on the last byte
  expectCell7Refused("cut.db", cut, "malformed varint at byte 2");
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
        testing::addBox(
            scene, "b", {-26.0f + 18.0f * float(i), 0.0f, -26.0f + 18.0f * float(k)},
            {-16.0f + 18.0f * float(i), 8.0f + 3.0f * float(i), -16.0f + 18.0f * float(k)});
    finalizeScene(scene);
    triangles = flattenScene(scene, true);
    rays = makeEmbreeRayQuery(triangles);
    freeSpace = FreeSpace::build(*rays, Solids::build(triangles), scene.bounds());
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
        const glm::vec2 blo(-26.0f + 18.0f * float(i), -26.0f + 18.0f * float(k)),
            bhi = blo + glm::vec2(10.0f);
        EXPECT_FALSE(lo.x >= blo.x && hi.x <= bhi.x && lo.y >= blo.y && hi.y <= bhi.y)
            << "cell " << c;
      }
  }
}

TEST(PvsBake, StoresForEveryCellThePvsOfItsBox) {
  TempDir dir;
  BakeOptions options = townBake();
  options.coarseToFine = false;
  const BakeReport report =
      bakePvs(town().scene, *town().pvs, town().freeSpace, options, dir / "t.db");
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
  const auto insideClosed = testing::unservedViewpointRule(town().triangles, *town().rays);
  for (uint32_t c : a.cellIndices()) {
    const auto fa = *a.cell(c), fb = *b.cell(c);
    EXPECT_TRUE(std::includes(fa.begin(), fa.end(), fb.begin(), fb.end())) << "cell " << c;
    SampledVisibilityOptions gt;
    gt.points = 12;
    gt.resolution = 48;
    gt.skipViewpoint = insideClosed;
    for (uint32_t f :
         sampleVisibleFaces(*town().rays, town().triangles, grid.cellBox(grid.cellAt(c)), gt).faces)
      EXPECT_TRUE(std::binary_search(fb.begin(), fb.end(), f))
          << "cell " << c << " misses face " << f;
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
  EXPECT_THROW(bakePvs(town().scene, *town().pvs, town().freeSpace, dying, dir / "resumed.db"),
               std::runtime_error);
  const fs::path journal = dir / "resumed.db.journal";
  ASSERT_TRUE(fs::exists(journal));
  EXPECT_FALSE(fs::exists(dir / "resumed.db"));
  fs::resize_file(journal, fs::file_size(journal) - 3);
  const BakeReport report =
      bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "resumed.db");
  EXPECT_GT(report.resumedCells, 0u);
  EXPECT_LT(report.computedCells, report.freeCells);
  std::ifstream a(dir / "fresh.db", std::ios::binary), b(dir / "resumed.db", std::ios::binary);
  const std::string ba((std::istreambuf_iterator<char>(a)), {}),
      bb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(ba, bb);
}

// One record of a bake journal (pvs_bake.cpp): [index u32][count u32]
// [bytes u32][face list][FNV-1a 64 of what precedes it], after a 16-byte header.
struct JournalRecordAt {
  size_t offset = 0;
  uint32_t index = 0, count = 0, bytes = 0;
  size_t size() const { return 12 + bytes + 8; }
};

std::vector<JournalRecordAt> journalRecords(const std::string& j) {
  std::vector<JournalRecordAt> out;
  size_t pos = 16;
  while (pos + 12 <= j.size()) {
    JournalRecordAt r;
    r.offset = pos;
    std::memcpy(&r.index, j.data() + pos, 4);
    std::memcpy(&r.count, j.data() + pos + 4, 4);
    std::memcpy(&r.bytes, j.data() + pos + 8, 4);
    if (pos + r.size() > j.size()) break;
    out.push_back(r);
    pos += r.size();
  }
  EXPECT_EQ(pos, j.size()) << "the journal should hold whole records";
  return out;
}

// Runs a bake of the town that dies after `cells` cells, leaving its journal.
std::string dyingBakeJournal(const TempDir& dir, const std::string& out, size_t cells) {
  BakeOptions dying = townBake();
  dying.threads = 1;
  size_t calls = 0;
  dying.progress = [&](size_t, size_t) {
    if (++calls == cells + 1) throw std::runtime_error("killed");  // the first call reports 0 cells
  };
  EXPECT_THROW(bakePvs(town().scene, *town().pvs, town().freeSpace, dying, dir / out),
               std::runtime_error);
  return readBytes(dir / (out + ".journal"));
}

TEST(PvsBake, ResumesPastABitFlipInTheJournalFromItsValidPrefixWarnsAndGivesTheSameDatabase) {
  TempDir dir;
  bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "fresh.db");
  std::string journal = dyingBakeJournal(dir, "resumed.db", 11);
  const std::vector<JournalRecordAt> records = journalRecords(journal);
  ASSERT_EQ(records.size(), 11u);
  // One bit in the middle of the middle record's face list (its checksum,
  // should the list be empty).
  const JournalRecordAt& bad = records[5];
  journal[bad.offset + 12 + bad.bytes / 2] ^= 0x04;
  writeBytes(dir / "resumed.db.journal", journal);

  CapturedLog log;
  const BakeReport report =
      bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "resumed.db");
  EXPECT_EQ(report.resumedCells, 5u);
  EXPECT_EQ(report.computedCells, report.shardCells - 5);
  EXPECT_EQ(readBytes(dir / "resumed.db"), readBytes(dir / "fresh.db"));
  EXPECT_FALSE(fs::exists(dir / "resumed.db.journal"));
  const std::string warnings = log.warnings();
  EXPECT_THAT(warnings, HasSubstr((dir / "resumed.db.journal").string()));
  EXPECT_THAT(warnings, HasSubstr(fmt::format(
                            "corrupt record at byte offset {} (checksum mismatch) after 5 good "
                            "records; dropping the {} bytes from there: that record and the 5 "
                            "records after it.",
                            bad.offset, journal.size() - bad.offset)));
}

TEST(PvsBake, RecomputesAJournalRecordWhoseChecksumPassesButThatNamesAFaceBeyondTheScene) {
  TempDir dir;
  bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "fresh.db");
  const std::string journal = dyingBakeJournal(dir, "resumed.db", 6);
  const std::vector<JournalRecordAt> records = journalRecords(journal);
  ASSERT_EQ(records.size(), 6u);
  // Record 2 gets the scene's face count (one past the last face ID) added to
  // its list and a correct checksum, as a buggy or crafted writer could leave.
  const JournalRecordAt& r = records[2];
  std::vector<uint32_t> faces = decodeFaceList(
      reinterpret_cast<const uint8_t*>(journal.data() + r.offset + 12), r.bytes, r.count);
  faces.push_back(town().scene.faceCount);
  const std::string list = asString(encodeFaceList(faces));
  std::string record(12, '\0');
  const uint32_t head[3] = {r.index, uint32_t(faces.size()), uint32_t(list.size())};
  std::memcpy(record.data(), head, 12);
  record += list;
  const uint64_t sum = referenceFnv1a64(record);
  record.append(reinterpret_cast<const char*>(&sum), 8);
  writeBytes(dir / "resumed.db.journal",
             journal.substr(0, r.offset) + record + journal.substr(r.offset + r.size()));

  CapturedLog log;
  const BakeReport report =
      bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "resumed.db");
  EXPECT_EQ(report.resumedCells, 2u);
  EXPECT_EQ(readBytes(dir / "resumed.db"), readBytes(dir / "fresh.db"));
  EXPECT_THAT(log.warnings(),
              HasSubstr(fmt::format("is face {}, not below the face count {}",
                                    town().scene.faceCount, town().scene.faceCount)));
  EXPECT_THAT(log.warnings(), HasSubstr("that record and the 3 records after it."));
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
  EXPECT_THROW(bakePvs(town().scene, *town().pvs, town().freeSpace, other, dir / "x.db"),
               std::runtime_error);
  const BakeReport report =
      bakePvs(town().scene, *town().pvs, town().freeSpace, townBake(), dir / "x.db");
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
    shardCells += bakePvs(town().scene, *town().pvs, town().freeSpace, o,
                          dir / ("s" + std::to_string(i) + ".db"))
                      .shardCells;
  }
  mergePvsDatabases({dir / "s0.db", dir / "s1.db", dir / "s2.db"}, dir / "merged.db");
  const PvsDatabase all = PvsDatabase::open(dir / "all.db"),
                    merged = PvsDatabase::open(dir / "merged.db");
  EXPECT_EQ(shardCells, all.cellCount());
  ASSERT_EQ(merged.cellIndices(), all.cellIndices());
  for (uint32_t c : all.cellIndices()) EXPECT_EQ(*merged.cell(c), *all.cell(c));

  BakeOptions coarse = townBake();
  coarse.cellSize = {8.0f, 2.0f, 8.0f};
  bakePvs(town().scene, *town().pvs, town().freeSpace, coarse, dir / "coarse.db");
  EXPECT_THAT(errorOf([&] {
                mergePvsDatabases({dir / "all.db", dir / "coarse.db"}, dir / "bad.db");
              }),
              HasSubstr("coarse.db"));
  EXPECT_FALSE(fs::exists(dir / "bad.db"));
  BakeOptions badShard = townBake();
  badShard.shardIndex = 3;
  badShard.shardCount = 3;
  EXPECT_THAT(errorOf([&] {
                bakePvs(town().scene, *town().pvs, town().freeSpace, badShard, dir / "z.db");
              }),
              HasSubstr("shard 3/3"));
}

}  // namespace
}  // namespace vistream
