#include "server/visibility/pvs_bake.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <map>
#include <mutex>

#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for_each.h>

#include "common/core/error.h"
#include "common/core/timer.h"

namespace vistream {
namespace {

constexpr float kEyeLow = 0.2f, kEyeHigh = 2.0f;  // metres above the floor a viewer's eye can be
constexpr char kJournalMagic[8] = {'V', 'S', 'J', 'R', 'N', 'L', '1', '\0'};

uint64_t fnv(const void* data, size_t size, uint64_t h = 1469598103934665603ull) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
  return h;
}

// Everything that changes a bake's answer: a journal from other parameters
// must not be resumed.
uint64_t bakeFingerprint(const PvsDatabaseHeader& h, const BakeOptions& o) {
  uint64_t f = fnv(&h.sceneFingerprint, sizeof h.sceneFingerprint);
  f = fnv(&h.gridLo, sizeof h.gridLo, f);
  f = fnv(&h.cellSize, sizeof h.cellSize, f);
  f = fnv(&h.dims, sizeof h.dims, f);
  f = fnv(h.method.data(), h.method.size(), f);
  const uint32_t shard[2] = {o.shardIndex, o.shardCount};
  f = fnv(shard, sizeof shard, f);
  const uint8_t flags[4] = {o.pvs.boxStage, o.pvs.incremental, o.pvs.dropOccludedOccluders, o.pvs.removeRedundantLines};
  f = fnv(flags, sizeof flags, f);
  const uint64_t large = o.pvs.largeOccluders;
  return fnv(&large, sizeof large, f);
}

// Journal: magic, fingerprint, then records [index u32][count u32][bytes u32][payload][fnv u64].
class Journal {
 public:
  Journal(const std::filesystem::path& path, uint64_t fingerprint, std::map<uint32_t, std::vector<uint32_t>>& done)
      : path_(path) {
    const bool exists = std::filesystem::exists(path);
    if (exists) readExisting(fingerprint, done);
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd_ < 0) throwInputError("{}: cannot open bake journal: {}", path.string(), std::strerror(errno));
    if (::lseek(fd_, 0, SEEK_END) == 0) {
      char header[16];
      std::memcpy(header, kJournalMagic, 8);
      std::memcpy(header + 8, &fingerprint, 8);
      writeAll(header, sizeof header);
    }
  }
  ~Journal() {
    if (fd_ >= 0) ::close(fd_);
  }

  // Thread-safe append of one finished cell.
  void append(uint32_t index, const std::vector<uint32_t>& faces) {
    const std::vector<uint8_t> bytes = encodeFaceList(faces);
    std::vector<uint8_t> rec(12 + bytes.size() + 8);
    const uint32_t head[3] = {index, uint32_t(faces.size()), uint32_t(bytes.size())};
    std::memcpy(rec.data(), head, 12);
    std::memcpy(rec.data() + 12, bytes.data(), bytes.size());
    const uint64_t sum = fnv(rec.data(), 12 + bytes.size());
    std::memcpy(rec.data() + 12 + bytes.size(), &sum, 8);
    std::lock_guard lock(mutex_);
    writeAll(rec.data(), rec.size());
  }

  void remove() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }

 private:
  void writeAll(const void* data, size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    while (n > 0) {
      const ssize_t w = ::write(fd_, p, n);
      if (w < 0) {
        if (errno == EINTR) continue;
        throwInputError("{}: journal write failed: {}", path_.string(), std::strerror(errno));
      }
      p += w;
      n -= size_t(w);
    }
  }

  void readExisting(uint64_t fingerprint, std::map<uint32_t, std::vector<uint32_t>>& done) {
    std::FILE* f = std::fopen(path_.c_str(), "rb");
    if (!f) return;
    char header[16];
    uint64_t fp = 0;
    size_t valid = 0;
    if (std::fread(header, 1, 16, f) == 16 && std::memcmp(header, kJournalMagic, 8) == 0) {
      std::memcpy(&fp, header + 8, 8);
      if (fp == fingerprint) {
        valid = 16;
        while (true) {
          uint32_t head[3];
          if (std::fread(head, 4, 3, f) != 3) break;
          if (head[2] > (64u << 20)) break;
          std::vector<uint8_t> rec(12 + head[2]);
          std::memcpy(rec.data(), head, 12);
          uint64_t sum = 0;
          if (std::fread(rec.data() + 12, 1, head[2], f) != head[2] || std::fread(&sum, 8, 1, f) != 1) break;
          if (fnv(rec.data(), rec.size()) != sum) break;
          try {
            done[head[0]] = decodeFaceList(rec.data() + 12, head[2], head[1]);
          } catch (const InputError&) {
            break;
          }
          valid += rec.size() + 8;
        }
      } else {
        spdlog::warn("{}: journal is from a bake with other parameters; starting over", path_.string());
      }
    }
    std::fclose(f);
    // Drop a torn tail (or a foreign journal) so appends continue cleanly.
    std::error_code ec;
    std::filesystem::resize_file(path_, valid, ec);
    if (ec) throwInputError("{}: cannot truncate journal: {}", path_.string(), ec.message());
    if (!done.empty()) spdlog::info("resuming bake: {} cells already in {}", done.size(), path_.string());
  }

  std::filesystem::path path_;
  int fd_ = -1;
  std::mutex mutex_;  // guards appends to fd_
};

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
    if (lo > hi) throwInputError("scene '{}' has no free space to bake cells over", scene.name);
    region = Box3f({b.lo.x, lo + kEyeLow, b.lo.z}, {b.hi.x, hi + kEyeHigh, b.hi.z});
  }
  if (region.empty()) throwInputError("the bake region is empty");
  const glm::vec3 dims = glm::ceil(region.extent() / options.cellSize);
  if (double(dims.x) * double(dims.y) * double(dims.z) > 1e9)
    throwInputError("cell size {}x{}x{} gives more than 10^9 cells", options.cellSize.x, options.cellSize.y,
                    options.cellSize.z);
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

BakeReport bakePvs(const Scene& scene, const EpsilonPvs& pvs, const FreeSpace& fs, const BakeOptions& options,
                   const std::filesystem::path& out) {
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
  header.method = "paper";

  // Blocks of 2 x 1 x 2 cells: the coarse level, and the unit of sharding.
  std::map<uint64_t, std::vector<uint32_t>> blocks;
  for (uint32_t c : cells) {
    const glm::ivec3 ijk = grid.cellAt(c);
    const uint64_t key = (uint64_t(ijk.z / 2) * uint64_t(grid.dims().y) + uint64_t(ijk.y)) * uint64_t(grid.dims().x) +
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
  Journal journal(out.string() + ".journal", bakeFingerprint(header, options), done);
  report.resumedCells = done.size();
  std::mutex doneMutex;  // guards `done` while workers add cells
  std::atomic<size_t> progress{0};
  for (const auto& b : mine)
    for (uint32_t c : b)
      if (done.count(c)) ++progress;
  if (options.progress) options.progress(progress.load(), report.shardCells);

  std::optional<tbb::global_control> limit;
  if (options.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, options.threads);
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
    if (options.coarseToFine && pending.size() > 1) {
      Box3f box;
      for (uint32_t c : pending) box.extend(grid.cellBox(grid.cellAt(c)));
      coarse = pvs.compute(box, options.pvs).faces;
      cellOptions.candidateFaces = &coarse;
    }
    for (uint32_t c : pending) {
      PvsResult r = pvs.compute(grid.cellBox(grid.cellAt(c)), cellOptions);
      journal.append(c, r.faces);
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
      report.totalFaces += done[c].size();
      shardCells[c] = std::move(done[c]);
    }
  writePvsDatabase(out, header, shardCells);
  journal.remove();
  report.timeMs = clock.ms();
  const unsigned threads = options.threads ? options.threads : unsigned(tbb::info::default_concurrency());
  report.meanCellMs = report.computedCells ? report.timeMs * threads / double(report.computedCells) : 0.0;
  return report;
}

void mergePvsDatabases(const std::vector<std::filesystem::path>& inputs, const std::filesystem::path& out) {
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
        throwInputError("{}: cell {} differs from the same cell in an earlier input", inputs[i].string(), c);
    }
  }
  writePvsDatabase(out, header, cells);
}

}  // namespace vistream
