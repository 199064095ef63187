#include "server/visibility/pvs_bake.h"

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for_each.h>

#include <array>
#include <atomic>
#include <map>
#include <memory>
#include <mutex>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/core/timer.h"
#include "server/bake/bake_journal.h"

namespace vistream {
namespace {

constexpr float kEyeLow = 0.2f, kEyeHigh = 2.0f;  // metres above the floor a viewer's eye can be
// Journal format 2 (format 1 seeded its hashes with a wrong FNV offset
// basis, and its fingerprint missed the coarse-to-fine switch).
constexpr std::array<char, 8> kPvsJournalMagic = {'V', 'S', 'J', 'R', 'N', 'L', '2', '\0'};

// Everything that changes a bake's answer: a journal from other parameters
// must not be resumed.
uint64_t bakeFingerprint(const PvsDatabaseHeader& h, const BakeOptions& o) {
  uint64_t f = fnv1a64(&h.sceneFingerprint, sizeof h.sceneFingerprint);
  f = fnv1a64(&h.sceneFaces, sizeof h.sceneFaces, f);
  f = fnv1a64(&h.gridLo, sizeof h.gridLo, f);
  f = fnv1a64(&h.cellSize, sizeof h.cellSize, f);
  f = fnv1a64(&h.dims, sizeof h.dims, f);
  f = fnv1a64(h.method.data(), h.method.size(), f);
  const uint32_t shard[2] = {o.shardIndex, o.shardCount};
  f = fnv1a64(shard, sizeof shard, f);
  // The fused stage shows in the method's name.
  const uint8_t flags[6] = {
      o.pvs.boxStage, o.pvs.incremental, o.pvs.dropOccludedOccluders, o.pvs.removeRedundantLines,
      o.coarseToFine, o.pvs.backFaces};
  f = fnv1a64(flags, sizeof flags, f);
  const uint64_t large = o.pvs.largeOccluders;
  return fnv1a64(&large, sizeof large, f);
}

}  // namespace

ViewCellGrid bakeGrid(const Scene& scene, const FreeSpace& fs, const BakeOptions& options) {
  if (!(options.cellSize.x > 0.0f && options.cellSize.y > 0.0f && options.cellSize.z > 0.0f))
    throwInputError("cell size must be positive in every axis");
  Box3f region;
  if (options.region) {
    region = *options.region;
  } else {
    const Box3f b = scene.bounds();
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    for (const auto& c : fs.walkableColumns()) {
      lo = std::min(lo, fs.floorHeight(c.x, c.y));
      hi = std::max(hi, fs.floorHeight(c.x, c.y));
    }
    if (lo > hi)
      throwInputError("scene '{}' has no free space to bake cells over: {}", scene.name,
                      fs.emptyReason());
    region = Box3f({b.lo.x, lo + kEyeLow, b.lo.z}, {b.hi.x, hi + kEyeHigh, b.hi.z});
  }
  if (region.empty()) throwInputError("the bake region is empty");
  const glm::vec3 dims = glm::ceil(region.extent() / options.cellSize);
  if (double(dims.x) * double(dims.y) * double(dims.z) > 1e9)
    throwInputError("cell size {}x{}x{} gives more than 10^9 cells", options.cellSize.x,
                    options.cellSize.y, options.cellSize.z);
  return ViewCellGrid(region, options.cellSize);
}

std::vector<uint32_t> freeSpaceCells(const Scene&, const ViewCellGrid& grid, const FreeSpace& fs) {
  std::vector<uint8_t> mark(grid.cellCount(), 0);
  const glm::ivec3 dims = grid.dims();
  const glm::vec3 lo = grid.origin(), size = grid.cellSize();
  const float half = 0.5f * fs.cellSize();
  for (const auto& c : fs.walkableColumns()) {
    const glm::vec2 xz = fs.columnCentre(c.x, c.y);
    const float floor = fs.floorHeight(c.x, c.y);
    // The column's footprint may straddle cells: mark every cell it touches.
    const int i0 = std::max(0, int(std::floor((xz.x - half - lo.x) / size.x)));
    const int i1 = std::min(dims.x - 1, int(std::floor((xz.x + half - lo.x) / size.x)));
    const int k0 = std::max(0, int(std::floor((xz.y - half - lo.z) / size.z)));
    const int k1 = std::min(dims.z - 1, int(std::floor((xz.y + half - lo.z) / size.z)));
    const int j0 = std::max(0, int(std::floor((floor + kEyeLow - lo.y) / size.y)));
    const int j1 = std::min(dims.y - 1, int(std::floor((floor + kEyeHigh - lo.y) / size.y)));
    for (int k = k0; k <= k1; ++k)
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i) mark[grid.linearIndex({i, j, k})] = 1;
  }
  std::vector<uint32_t> out;
  for (size_t i = 0; i < mark.size(); ++i)
    if (mark[i]) out.push_back(uint32_t(i));
  return out;
}

BakeReport bakePvs(const Scene& scene, const EpsilonPvs& pvs, const FreeSpace& fs,
                   const BakeOptions& options, const std::filesystem::path& out) {
  if (options.shardCount == 0 || options.shardIndex >= options.shardCount)
    throwInputError("shard {}/{} is not valid (expected i/n with 0 <= i < n)", options.shardIndex,
                    options.shardCount);
  Stopwatch clock;
  BakeReport report;
  const ViewCellGrid grid = bakeGrid(scene, fs, options);
  const std::vector<uint32_t> cells = freeSpaceCells(scene, grid, fs);
  report.gridCells = grid.cellCount();
  report.freeCells = cells.size();

  PvsDatabaseHeader header;
  header.sceneName = scene.name;
  header.sceneFingerprint = sceneFingerprint(scene);
  header.sceneFaces = scene.faceCount;
  header.origin = scene.origin;
  header.gridLo = grid.origin();
  header.cellSize = grid.cellSize();
  header.dims = grid.dims();
  header.method = std::string(options.pvs.backFaces ? "paper+back-faces" : "paper") +
                  (options.pvs.planarFusion ? "+planar" : "") +
                  (pvs.fusion() && options.pvs.fusion ? "+horizons" : "");

  // Blocks of 2 x 1 x 2 cells: the coarse level, and the unit of sharding.
  std::map<uint64_t, std::vector<uint32_t>> blocks;
  for (uint32_t c : cells) {
    const glm::ivec3 ijk = grid.cellAt(c);
    const uint64_t key = (uint64_t(ijk.z / 2) * uint64_t(grid.dims().y) + uint64_t(ijk.y)) *
                             uint64_t(grid.dims().x) +
                         uint64_t(ijk.x / 2);
    blocks[key].push_back(c);
  }
  std::vector<std::vector<uint32_t>> mine;
  size_t blockIndex = 0;
  for (auto& [key, members] : blocks) {
    if (blockIndex++ % options.shardCount == options.shardIndex) mine.push_back(std::move(members));
  }
  for (const auto& b : mine) report.shardCells += b.size();

  std::map<uint32_t, std::vector<uint32_t>> done;
  // A journal record: the cell's face count as `aux`, its face list as payload.
  BakeJournal journal(out.string() + ".journal", kPvsJournalMagic, bakeFingerprint(header, options),
                      [&](const JournalRecordView& r) -> std::string {
                        if (r.index >= grid.cellCount())
                          return fmt::format("cell index {} is outside the grid of {} cells",
                                             r.index, grid.cellCount());
                        try {
                          done[r.index] = decodeFaceList(r.payload.data(), r.payload.size(), r.aux,
                                                         header.sceneFaces);
                        } catch (const InputError& e) {
                          return e.what();
                        }
                        return {};
                      });
  std::mutex doneMutex;  // guards `done` while workers add cells
  std::atomic<size_t> progress{0};
  for (const auto& b : mine)
    for (uint32_t c : b)
      if (done.count(c)) ++progress;
  report.resumedCells = progress.load();
  if (options.progress) options.progress(progress.load(), report.shardCells);

  std::optional<tbb::global_control> limit;
  if (options.threads > 0)
    limit.emplace(tbb::global_control::max_allowed_parallelism, options.threads);
  std::atomic<size_t> computed{0};
  tbb::parallel_for_each(mine.begin(), mine.end(), [&](const std::vector<uint32_t>& block) {
    std::vector<uint32_t> pending;
    {
      std::lock_guard lock(doneMutex);
      for (uint32_t c : block)
        if (!done.count(c)) pending.push_back(c);
    }
    if (pending.empty()) return;
    PvsOptions cellOptions = options.pvs;
    std::vector<uint32_t> coarse;
    // The coarse level is always the whole block's PVS, even when some of its
    // cells came from the journal: a cell's answer depends on its candidate
    // faces, so this keeps a resumed bake identical to one run straight through.
    if (options.coarseToFine && block.size() > 1) {
      Box3f box;
      for (uint32_t c : block) box.extend(grid.cellBox(grid.cellAt(c)));
      // Without the fused stage: the horizons of a block cost several times
      // those of its cells (their wedges are wider and reach farther), and
      // each cell runs them on its own candidates anyway.
      PvsOptions coarseOptions = options.pvs;
      coarseOptions.fusion = false;
      coarse = pvs.compute(box, coarseOptions).faces;
      cellOptions.candidateFaces = &coarse;
    }
    for (uint32_t c : pending) {
      PvsResult r = pvs.compute(grid.cellBox(grid.cellAt(c)), cellOptions);
      journal.append(c, uint32_t(r.faces.size()), encodeFaceList(r.faces));
      {
        std::lock_guard lock(doneMutex);
        done[c] = std::move(r.faces);
      }
      ++computed;
      const size_t p = ++progress;
      if (options.progress) options.progress(p, report.shardCells);
    }
  });
  report.computedCells = computed.load();
  std::map<uint32_t, std::vector<uint32_t>> shardCells;
  for (const auto& b : mine)
    for (uint32_t c : b) {
      const auto it = done.find(c);
      VS_CHECK(it != done.end());  // every cell of the shard was resumed or computed
      report.totalFaces += it->second.size();
      shardCells[c] = std::move(it->second);
    }
  writePvsDatabase(out, header, shardCells);
  journal.remove();
  report.timeMs = clock.ms();
  const unsigned threads =
      options.threads ? options.threads : unsigned(tbb::info::default_concurrency());
  report.meanCellMs =
      report.computedCells ? report.timeMs * threads / double(report.computedCells) : 0.0;
  return report;
}

void mergePvsDatabases(const std::vector<std::filesystem::path>& inputs,
                       const std::filesystem::path& out) {
  if (inputs.empty()) throwInputError("merge needs at least one database");
  std::map<uint32_t, std::vector<uint32_t>> cells;
  PvsDatabaseHeader header;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const PvsDatabase db = PvsDatabase::open(inputs[i]);
    if (i == 0) {
      header = db.header();
    } else if (!header.compatible(db.header())) {
      throwInputError("{}: baked from another scene, grid or method than {}", inputs[i].string(),
                      inputs[0].string());
    }
    for (uint32_t c : db.cellIndices()) {
      auto faces = *db.cell(c);
      const auto [it, inserted] = cells.try_emplace(c, std::move(faces));
      if (!inserted && it->second != *db.cell(c))
        throwInputError("{}: cell {} differs from the same cell in an earlier input",
                        inputs[i].string(), c);
    }
  }
  writePvsDatabase(out, header, cells);
}

}  // namespace vistream
