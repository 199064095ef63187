#include "server/stream/stream_world.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <iterator>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/core/timer.h"
#include "common/light/lighting_cache.h"
#include "common/raycast/ray_query.h"
#include "common/world/free_space.h"
#include "common/world/static_world.h"
#include "protocol/geometry/scene_faces.h"
#include "server/visibility/pvs_bake.h"

namespace vistream {

StreamPolicy parseStreamPolicy(const std::string& name) {
  if (name == "visibility") return StreamPolicy::Visibility;
  if (name == "radius") return StreamPolicy::Radius;
  throwInputError("--policy: expected visibility or radius, got '{}'", name);
}

const char* streamPolicyName(StreamPolicy p) {
  return p == StreamPolicy::Visibility ? "visibility" : "radius";
}

namespace {

size_t faceListBytes(const FaceList& f) {
  return f.size() * sizeof(uint32_t) + 64;
}

}  // namespace

StreamWorld::StreamWorld(Scene scene, const StreamWorldOptions& options)
    : scene_(std::move(scene)), work_(options.maxQueuedPrefetch) {
  Stopwatch clock;
  if (!options.pvsDatabase.empty()) {
    database_.emplace(PvsDatabase::open(options.pvsDatabase));
    const PvsDatabaseHeader& h = database_->header();
    if (h.sceneFingerprint != sceneFingerprint(scene_) || h.sceneFaces != scene_.faceCount)
      throwInputError(
          "--pvs-db {}: baked for scene '{}' ({} faces), not for this scene '{}' ({} faces)",
          options.pvsDatabase.string(), h.sceneName, h.sceneFaces, scene_.name, scene_.faceCount);
    grid_ = h.grid();
    StaticWorldOptions worldOptions;
    worldOptions.ground = options.ground;
    worldOptions.parts = StaticWorldParts::Ground;
    ground_ = buildStaticWorld(scene_, worldOptions).ground;
  } else {
    if (!(options.cellSize > 0.0f)) throwInputError("--cell-size must be positive");
    StaticWorldOptions worldOptions;
    worldOptions.ground = options.ground;
    statics_ = std::make_unique<StaticWorld>(buildStaticWorld(scene_, worldOptions));
    ground_ = statics_->ground;
    BakeOptions bo;
    bo.cellSize = glm::vec3(options.cellSize);
    grid_ = bakeGrid(scene_, statics_->freeSpace, bo);
  }
  if (!options.impostorDatabase.empty()) {
    if (!database_)
      throwInputError(
          "--impostor-db {} needs --pvs-db: its cells are those of the PVS database it "
          "was baked from",
          options.impostorDatabase.string());
    impostors_.emplace(ImpostorDatabase::open(options.impostorDatabase));
    if (!impostors_->header().pvs.compatible(database_->header()))
      throwInputError(
          "--impostor-db {}: baked from another PVS database (scene '{}', {} cells) "
          "than --pvs-db {}",
          options.impostorDatabase.string(), impostors_->header().pvs.sceneName,
          impostors_->cellCount(), options.pvsDatabase.string());
    spdlog::info("impostors of {} cells from {}", impostors_->cellCount(),
                 options.impostorDatabase.string());
  }
  VS_CHECK_LT(grid_.cellCount(), size_t(kCoarseKey));  // keys leave the top bit for coarse cells
  culling_ = std::make_unique<CullingScene>(scene_);

  // Baked lighting of the static triangles, in flattenScene's order.
  std::optional<SceneLighting> lit;
  if (options.lighting) {
    lit = lightScene(scene_, flattenScene(scene_, /*staticOnly=*/true), options.lightingOptions,
                     options.lightingCache);
    backdrop_ = lit->backdrop;
  }
  // Per-face triangles, colours and bounds, in face-ID order.
  faces_ = wire::sceneFaces(scene_, lit ? &lit->load.grid : nullptr, &faceBoxes_);
  // Faces by X/Z cell: at least 8 m cells, at most about 512 along the longer side.
  const Box3f b = scene_.bounds();
  if (!b.empty())
    faceGrid_ =
        XzGrid(b, std::max(8.0f, std::max(b.hi.x - b.lo.x, b.hi.z - b.lo.z) / 512.0f), faceBoxes_);
  pvsCache_ = std::make_unique<AsyncCache<uint32_t, FaceList>>(
      options.pvsCacheCells, [this](const uint32_t& c) { return computePvs(c); },
      [this](const uint32_t& c, const char* what) {
        const glm::ivec3 i = grid_.cellAt(c & ~kCoarseKey);
        spdlog::error("PVS of cell ({}, {}, {}) failed: {}", i.x, i.y, i.z, what);
      },
      options.pvsCacheBytes, faceListBytes, &work_);
  faceSetCache_ = std::make_unique<AsyncCache<FaceSetKey, FaceList, FaceSetKeyHash>>(
      options.faceSetCacheEntries,
      [this](const FaceSetKey& k) {
        const Box3f box = pvsKeyBox(k.cell);
        FaceList near = facesWithin(box, float(k.radiusCm) / 100.0f);
        if (k.policy == StreamPolicy::Radius) {
          // A coarse block's radius set is an unculled set (see cellFaceSet).
          if (k.cell & kCoarseKey) ++unculledComputed_;
          return near;
        }
        if (!database_) return computeNearPvs(k, box, near);
        FaceListPtr pvs = pvsCache_->find(k.cell);
        const FaceList computed = pvs ? FaceList{} : computePvs(k.cell);
        const FaceList& p = pvs ? *pvs : computed;
        FaceList out;
        std::set_intersection(p.begin(), p.end(), near.begin(), near.end(),
                              std::back_inserter(out));
        return out;
      },
      [this](const FaceSetKey& k, const char* what) {
        const glm::ivec3 i = grid_.cellAt(k.cell & ~kCoarseKey);
        spdlog::error("face set of cell ({}, {}, {}) failed: {}", i.x, i.y, i.z, what);
      },
      options.faceSetCacheBytes, faceListBytes, &work_);
  // Without a database every client needs the occluders at once: prepared
  // here (seconds on a big city) rather than by the first client's request.
  if (!database_) {
    horizons_ = makeHorizonFusion(scene_, options.fusion, statics_.get());
    if (!horizons_) statics_.reset();  // kept only for the horizons
    epsilonPvs();
  }
  spdlog::info(
      "stream world: scene '{}' ({} faces), {} x {} x {} cells of {:.1f} m, PVS {}, ready in "
      "{:.0f} ms",
      scene_.name, scene_.faceCount, grid_.dims().x, grid_.dims().y, grid_.dims().z,
      grid_.cellSize().x,
      database_ ? "from " + database_->path().string() : std::string("on demand"), clock.ms());
}

StreamWorld::~StreamWorld() = default;

const EpsilonPvs& StreamWorld::epsilonPvs() {
  std::call_once(pvsOnce_, [this] {
    Stopwatch clock;
    // Over the static world when there is one (no database): its solids
    // are built already.
    pvs_ = std::make_unique<EpsilonPvs>(scene_, OccluderOptions{}, statics_.get());
    pvs_->setFusion(horizons_.get());
    spdlog::info("PVS occluders prepared in {:.0f} ms", clock.ms());
  });
  return *pvs_;
}

uint32_t StreamWorld::pvsKey(const glm::ivec3& cell, CellLevel level) const {
  if (level == CellLevel::Fine) return uint32_t(grid_.linearIndex(cell));
  const glm::ivec3 first(cell.x & ~1, cell.y, cell.z & ~1);
  return kCoarseKey | uint32_t(grid_.linearIndex(first));
}

Box3f StreamWorld::coarseBox(const glm::ivec3& cell) const {
  const glm::ivec3 first(cell.x & ~1, cell.y, cell.z & ~1);
  Box3f box;
  for (int dz = 0; dz <= 1; ++dz)
    for (int dx = 0; dx <= 1; ++dx)
      if (grid_.contains(first + glm::ivec3(dx, 0, dz)))
        box.extend(grid_.cellBox(first + glm::ivec3(dx, 0, dz)));
  return box;
}

Box3f StreamWorld::pvsKeyBox(uint32_t key) const {
  const glm::ivec3 cell = grid_.cellAt(key & ~kCoarseKey);
  return key & kCoarseKey ? coarseBox(cell) : grid_.cellBox(cell);
}

// Only the faces within the radius are candidates: a face the client could
// see but that is outside the radius is not streamed anyway, and a face
// that is not a candidate is never an occludee, so the answer for every
// candidate is what the whole PVS would say of it or, where fewer occluders
// remain (an object left out is no longer an occluder of those behind it),
// a face more: never one less. On bigcity this costs about a fifth of the
// whole PVS. A fine cell with its parent's face set at hand (the same
// radius) takes only the parent's faces as candidates, as the bake's
// coarse-to-fine does: its set is then never larger than the parent's.
FaceList StreamWorld::computeNearPvs(const FaceSetKey& k, const Box3f& box, const FaceList& near) {
  PvsOptions options;
  options.candidateFaces = &near;
  options.fusion = !(k.cell & kCoarseKey);
  FaceList fromParent;
  if (!(k.cell & kCoarseKey)) {
    const glm::ivec3 cell = grid_.cellAt(k.cell);
    if (FaceListPtr parent =
            faceSetCache_->find({pvsKey(cell, CellLevel::Coarse), k.radiusCm, k.policy})) {
      std::set_intersection(parent->begin(), parent->end(), near.begin(), near.end(),
                            std::back_inserter(fromParent));
      options.candidateFaces = &fromParent;
    }
  }
  PvsResult result = epsilonPvs().compute(box, options);
  spdlog::debug(
      "near PVS of {} cell {}: {} of {} candidate faces in {:.1f} ms (box stage {:.1f} ms, "
      "face stage {:.1f} ms, {} lines)",
      k.cell & kCoarseKey ? "coarse" : "fine", k.cell & ~kCoarseKey, result.faces.size(),
      options.candidateFaces->size(), result.stats.timeMs, result.stats.boxStageMs,
      result.stats.faceStageMs, result.stats.linesCast);
  FaceList faces = std::move(result.faces);
  ++nearPvsComputed_;
  if (k.cell & kCoarseKey) ++coarseComputed_;
  return faces;
}

FaceList StreamWorld::computePvs(uint32_t key) {
  if (key & kCoarseKey) {
    PvsOptions coarse;
    coarse.fusion = false;
    FaceList faces = epsilonPvs().compute(pvsKeyBox(key), coarse).faces;
    ++coarseComputed_;
    return faces;
  }
  const uint32_t linear = key;
  if (database_) {
    // The database is validated when opened; should a cell still fail to
    // decode, it is computed on demand (and said once) rather than lost.
    try {
      if (auto faces = database_->cell(linear)) {
        ++pvsFromDatabase_;
        return std::move(*faces);
      }
    } catch (const std::exception& e) {
      std::call_once(databaseFailureLogged_, [&] {
        spdlog::error("{}: {}; serving such cells by on-demand computation",
                      database_->path().string(), e.what());
      });
    }
  }
  // Coarse-to-fine, as the bake: with the parent's PVS cached, only its faces
  // are candidates (the parent's PVS holds every face the cell can see).
  const glm::ivec3 cell = grid_.cellAt(linear);
  PvsOptions options;
  const FaceListPtr parent = pvsCache_->find(pvsKey(cell, CellLevel::Coarse));
  if (parent) options.candidateFaces = parent.get();
  return epsilonPvs().compute(grid_.cellBox(cell), options).faces;
}

std::optional<glm::ivec3> StreamWorld::cellOf(const glm::vec3& p) const {
  if (grid_.cellCount() == 0) return std::nullopt;
  // Clamped in float before the conversion: a point far outside the grid
  // would not fit an int.
  const glm::vec3 rel = glm::floor((p - grid_.origin()) / grid_.cellSize());
  return glm::ivec3(glm::clamp(rel, glm::vec3(0.0f), glm::vec3(grid_.dims() - 1)));
}

void StreamWorld::pvs(const glm::ivec3& cell, boost::asio::thread_pool& pool,
                      std::function<void(FaceListPtr)> done, const Interest& interest) {
  pvsCache_->get(
      uint32_t(grid_.linearIndex(cell)), pool.get_executor(),
      [this, start = std::chrono::steady_clock::now(), done = std::move(done)](FaceListPtr p) {
        pvsLatency_.observeSince(start);
        done(std::move(p));
      },
      interest);
}

FaceListPtr StreamWorld::cachedPvs(const glm::ivec3& cell) {
  return pvsCache_->find(uint32_t(grid_.linearIndex(cell)));
}

void StreamWorld::cellFaceSet(const glm::ivec3& cell, StreamPolicy policy, float radius,
                              boost::asio::thread_pool& pool, std::function<void(FaceListPtr)> done,
                              const Interest& interest) {
  cellFaceSet(cell, CellLevel::Fine, policy, radius, pool, std::move(done),
              CellWork{{}, interest, {}});
}

void StreamWorld::cellFaceSet(const glm::ivec3& cell, CellLevel level, StreamPolicy policy,
                              float radius, boost::asio::thread_pool& pool,
                              std::function<void(FaceListPtr)> done, CellWork work) {
  const FaceSetKey key = faceSetKey(cell, level, policy, radius);
  done = [this, start = std::chrono::steady_clock::now(), done = std::move(done)](FaceListPtr p) {
    faceSetLatency_.observeSince(start);
    done(std::move(p));
  };
  // One stage where the face set is computed from the near faces alone
  // (unculled sets are radius sets).
  if (key.policy == StreamPolicy::Radius || !database_) {
    faceSetCache_->get(key, pool.get_executor(), std::move(done), work.interest, work.priority,
                       std::move(work.dropped));
    return;
  }
  // The PVS first (shared with PvsRequest and avatars), then the face set.
  // The continuation holds the interest only weakly, so dropping it also
  // cancels the second stage. The drop callback is shared by the stages;
  // only the one waiting can be dropped.
  auto dropped = std::make_shared<std::function<void()>>(std::move(work.dropped));
  auto onDrop = [dropped] {
    if (*dropped) (*dropped)();
  };
  pvsCache_->get(
      key.cell, pool.get_executor(),
      [this, key, &pool, done = std::move(done), weak = std::weak_ptr<const int>(work.interest),
       unconditional = work.interest == nullptr, priority = work.priority,
       onDrop](FaceListPtr p) mutable {
        if (!p) return done(nullptr);
        Interest still = weak.lock();
        if (!unconditional && !still) return;  // cancelled between the stages
        faceSetCache_->get(key, pool.get_executor(), std::move(done), still, priority, onDrop);
      },
      work.interest, work.priority, onDrop);
}

// The cache key of a cell's face set. An unculled set is the coarse block's
// faces within the radius: the radius policy's set for the block's box.
StreamWorld::FaceSetKey StreamWorld::faceSetKey(const glm::ivec3& cell, CellLevel level,
                                                StreamPolicy policy, float radius) const {
  if (policy == StreamPolicy::Radius) level = CellLevel::Fine;
  const uint32_t radiusCm = uint32_t(std::lround(std::max(0.0f, radius) * 100.0f));
  if (level == CellLevel::Unculled)
    return {pvsKey(cell, CellLevel::Coarse), radiusCm, StreamPolicy::Radius};
  return {pvsKey(cell, level), radiusCm, policy};
}

bool StreamWorld::hasCellFaceSet(const glm::ivec3& cell, CellLevel level, StreamPolicy policy,
                                 float radius) const {
  return faceSetCache_->contains(faceSetKey(cell, level, policy, radius));
}

FaceList StreamWorld::facesWithin(const Box3f& box, float radius) const {
  FaceList out;
  for (uint32_t id : faceGrid_.itemsNear({box.lo.x - radius, box.lo.z - radius},
                                         {box.hi.x + radius, box.hi.z + radius}))
    if (faceBoxes_[id].distanceTo(box) <= radius) out.push_back(id);
  return out;  // ascending: itemsNear lists each face once, in order
}

bool StreamWorld::cellSeesCell(const glm::ivec3& viewerCell, const glm::ivec3& avatarCell) {
  const uint64_t key =
      (uint64_t(grid_.linearIndex(viewerCell)) << 32) | uint64_t(grid_.linearIndex(avatarCell));
  {
    std::lock_guard lock(cellPairsMutex_);
    if (auto it = cellPairs_.find(key); it != cellPairs_.end()) return it->second;
  }
  // The avatar stands on a floor within its cell: its body reaches 0.3 m
  // around and 0.2 m above the cell, and no lower than the cell's floor.
  Box3f body = grid_.cellBox(avatarCell);
  body.lo -= glm::vec3(0.3f, 0.0f, 0.3f);
  body.hi += glm::vec3(0.3f, 0.2f, 0.3f);
  const bool visible = !epsilonPvs().boxHidden(grid_.cellBox(viewerCell), body);
  std::lock_guard lock(cellPairsMutex_);
  if (cellPairs_.size() > (1u << 20)) cellPairs_.clear();  // bounded memory
  cellPairs_[key] = visible;
  return visible;
}

StreamWorld::CacheStats StreamWorld::cacheStats() const {
  return {pvsCache_->hits() + faceSetCache_->hits(),
          pvsCache_->misses() + faceSetCache_->misses(),
          pvsCache_->computed() + nearPvsComputed_,
          pvsFromDatabase_,
          pvsCache_->cancelled() + faceSetCache_->cancelled(),
          coarseComputed_,
          pvsCache_->dropped() + faceSetCache_->dropped(),
          unculledComputed_};
}

uint32_t StreamWorld::impostorViewCell(uint32_t linearCell) const {
  if (!impostors_) return linearCell;
  return impostors_->viewCellOf(linearCell).value_or(linearCell);
}

StreamWorld::ImpostorEntry StreamWorld::impostorEntry(uint32_t cell) const {
  if (!impostors_) return {nullptr, std::make_shared<const FaceList>()};
  // Every cell of a view cell is served its leader's record.
  const uint32_t linearCell = impostorViewCell(cell);
  {
    std::lock_guard lock(impostorMutex_);
    if (auto it = impostorCells_.find(linearCell); it != impostorCells_.end()) return it->second;
  }
  // Decoded outside the lock (a record holds megabytes of impostors);
  // two threads decoding the same cell at once keep the first.
  ImpostorEntry entry;
  auto replaced = std::make_shared<FaceList>();
  if (std::optional<CellRecord> record = impostors_->cell(linearCell)) {
    for (const StoredImpostor& s : record->impostors)
      replaced->insert(replaced->end(), s.faces.begin(), s.faces.end());
    std::sort(replaced->begin(), replaced->end());
    replaced->erase(std::unique(replaced->begin(), replaced->end()), replaced->end());
    entry.record = std::make_shared<const CellRecord>(std::move(*record));
  }
  entry.replaced = std::move(replaced);
  std::lock_guard lock(impostorMutex_);
  // Bounded: the records of the cells clients stand in and ahead of them;
  // past the bound the map starts afresh (a record is decoded again on demand).
  if (impostorCells_.size() >= kImpostorCellsKept) impostorCells_.clear();
  return impostorCells_.emplace(linearCell, std::move(entry)).first->second;
}

std::shared_ptr<const CellRecord> StreamWorld::impostorRecord(uint32_t linearCell) const {
  return impostorEntry(linearCell).record;
}

FaceListPtr StreamWorld::withImpostors(uint32_t linearCell, FaceListPtr faces) const {
  const ImpostorEntry entry = impostorEntry(linearCell);
  const FaceList none;
  const FaceList& replaced = *entry.replaced;
  const FaceList& geometry = entry.record ? entry.record->geometryFaces : none;
  if (replaced.empty() && geometry.empty()) return faces;
  FaceList kept;
  std::set_difference(faces->begin(), faces->end(), replaced.begin(), replaced.end(),
                      std::back_inserter(kept));
  auto out = std::make_shared<FaceList>();
  std::set_union(kept.begin(), kept.end(), geometry.begin(), geometry.end(),
                 std::back_inserter(*out));
  return out;
}

}  // namespace vistream
