// What the streaming server shares between all sessions: the scene, its view
// cell grid, per-face geometry ready to encode, the PVS of each cell
// (from a baked database or computed on demand, each once, in a bounded LRU
// cache) and the face set each cell streams under each policy.
//
// Policies: "visibility" streams, per cell, the faces of the cell's PVS
// within the near-field radius of the cell; "radius" (the baseline) streams
// every face within that radius, visible or not. Without a database, a
// cell's face set is computed with only the faces within the radius as
// candidates (PvsOptions::candidateFaces; see computeNearPvs), not as the
// whole PVS cut down to the radius: a superset of that, at a fraction of the
// cost.
//
// Coarse cells (without a database): blocks of 2 x 1 x 2 view cells, as the
// bake's coarse-to-fine level (server/visibility/pvs_bake.cpp). The PVS of a
// coarse cell is conservative for every viewpoint of the block, so it is a
// superset of each member cell's PVS and can be sent at once, shared by every
// client inside the block; a fine cell's PVS is computed with its coarse
// parent's PVS as the candidate faces (PvsOptions::candidateFaces) when that
// is cached, so it is never larger than the parent's. A coarse face set (the
// coarse PVS within the radius of the whole block) likewise contains the face
// set of each member cell at the same radius.
//
// Unculled sets (without a database): every face within the radius of a
// coarse block, no visibility computed (the radius policy's set for the
// block). It contains the block's coarse face set, hence each member cell's
// own, and costs a grid query rather than a PVS: what a client gets at once
// when the workers are behind, refined to the coarse and then the fine set
// when they catch up (stream_scheduler.h).
//
// Work order: PVS and face-set computations wait in one WorkQueue
// (work_queue.h) in order of urgency (a client's current cell before any
// prefetch, prefetch due soonest first, refinement last), with a bound on
// the prefetch and refinement waiting; abandonWork() drops everything
// waiting (a stopping server).
//
// Thread safety: immutable after construction except the caches and the work
// queue, which are thread-safe; every const member may be called from any
// thread. Work that computes (PVS, face sets) runs on the executor passed in,
// never inline.
#pragma once

#include <boost/asio/thread_pool.hpp>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/light/lighting.h"
#include "common/scene/scene.h"
#include "common/spatial/xz_grid.h"
#include "common/world/static_world.h"
#include "protocol/geometry/geometry_codec.h"
#include "server/impostor/impostor_database.h"
#include "server/stream/async_cache.h"
#include "server/stream/latency_histogram.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/hierarchical_culling.h"
#include "server/visibility/horizon_fusion.h"
#include "server/visibility/pvs_database.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

enum class StreamPolicy : uint8_t { Visibility, Radius };
StreamPolicy parseStreamPolicy(const std::string& name);  // throws InputError
const char* streamPolicyName(StreamPolicy p);

struct StreamWorldOptions {
  std::filesystem::path pvsDatabase;  // empty: compute every PVS on demand
  // Impostors for clients that want them (server/impostor/impostor_database.h);
  // baked from pvsDatabase, which it needs. Empty: none.
  std::filesystem::path impostorDatabase;
  float cellSize = 4.0f;  // without a database (metres), the paper's scale
  GroundChoice ground;    // without a database: the free space's ground (static_world.h)
  size_t pvsCacheCells = 4096;
  size_t faceSetCacheEntries = 4096;
  // Memory bounds of the two caches (face IDs at 4 bytes each). Clients pick
  // part of a face set's key (their radius), so entries alone do not bound it.
  size_t pvsCacheBytes = size_t(1) << 30;
  size_t faceSetCacheBytes = size_t(1) << 30;
  // Prefetch and refinement computations that may wait for a worker; beyond
  // this the least urgent are dropped (work_queue.h).
  size_t maxQueuedPrefetch = 64;
  // Without a database: occlusion horizons after the single occluders, for
  // view cells (not coarse blocks, whose horizons cost several times more),
  // as the bake does (horizon_fusion.h).
  FusionChoice fusion = FusionChoice::Auto;
  // Baked lighting streamed with every face (common/light/lighting.h): on by
  // default, read from or written to `lightingCache` (empty: bake without a
  // cache). Off: faces travel without colours and clients draw them flat.
  bool lighting = true;
  LightingOptions lightingOptions;
  std::filesystem::path lightingCache;
};

// Which PVS a face set is built from: a view cell's own, its coarse
// parent's (the 2 x 1 x 2 block holding it; see above), or none (Unculled:
// the coarse block's faces within the radius). Each level's set contains the
// one before it at the same radius.
enum class CellLevel : uint8_t { Fine, Coarse, Unculled };

// How a request for visibility work waits: its urgency, the requester's
// interest (see async_cache.h), and what to call instead of `done` if the
// queue drops it for its bound (never for rank Current).
struct CellWork {
  WorkPriority priority;
  Interest interest;
  std::function<void()> dropped;
};

using FaceList = std::vector<uint32_t>;  // sorted face IDs
using FaceListPtr = std::shared_ptr<const FaceList>;

class StreamWorld {
 public:
  // Takes the scene; throws InputError if a given database does not belong
  // to it.
  StreamWorld(Scene scene, const StreamWorldOptions& options);
  ~StreamWorld();

  const Scene& scene() const { return scene_; }
  const ViewCellGrid& grid() const { return grid_; }
  // The ground decision for the scene (static_world.h): clients draw an
  // assumed plane below the horizon.
  const GroundPlane& ground() const { return ground_; }
  const CullingScene& culling() const { return *culling_; }
  uint32_t faceCount() const { return scene_.faceCount; }
  const wire::FaceTriangles& face(uint32_t id) const { return faces_[id]; }
  // What a client holding the face stores: its decoded triangles, colours and ID.
  uint32_t faceBytes(uint32_t id) const {
    return uint32_t(faces_[id].corners.size() * sizeof(glm::vec3) +
                    faces_[id].colours.size() * sizeof(glm::u8vec3) + faces_[id].levels.size() + 8);
  }
  // The sky, ground and haze of the baked lighting (sent in Welcome); nothing
  // when lighting is off.
  const std::optional<Backdrop>& backdrop() const { return backdrop_; }
  glm::vec3 faceCentre(uint32_t id) const { return faceBoxes_[id].center(); }

  // The cell holding a local-frame point (clamped to the grid), or nothing
  // when the grid is empty.
  std::optional<glm::ivec3> cellOf(const glm::vec3& p) const;

  // The PVS of a cell (all faces, no radius), asynchronously on `pool`.
  // With an interest, the request lapses (no computation, no callback) once
  // the interest has expired before the computation started (async_cache.h).
  // `done` receives null if the computation failed (logged), never throws.
  void pvs(const glm::ivec3& cell, boost::asio::thread_pool& pool,
           std::function<void(FaceListPtr)> done, const Interest& interest = nullptr);
  FaceListPtr cachedPvs(const glm::ivec3& cell);
  // The faces a cell streams under a policy and radius, asynchronously; the
  // same interest and failure rules as pvs().
  void cellFaceSet(const glm::ivec3& cell, StreamPolicy policy, float radius,
                   boost::asio::thread_pool& pool, std::function<void(FaceListPtr)> done,
                   const Interest& interest = nullptr);
  // The same at a level (the radius policy has only Fine: Coarse and
  // Unculled are served as Fine), waiting in the work queue as `work` says.
  void cellFaceSet(const glm::ivec3& cell, CellLevel level, StreamPolicy policy, float radius,
                   boost::asio::thread_pool& pool, std::function<void(FaceListPtr)> done,
                   CellWork work);
  // Whether that face set is cached now (a request for it answers at once).
  bool hasCellFaceSet(const glm::ivec3& cell, CellLevel level, StreamPolicy policy,
                      float radius) const;
  // The closed box a coarse cell covers: the union of the member cells of
  // the block holding `cell` (clipped to the grid).
  Box3f coarseBox(const glm::ivec3& cell) const;
  // Whether clients get a coarse PVS first: only without a database (a
  // baked cell is read, not computed).
  bool coarseFirst() const { return !database_.has_value(); }

  // The order and bound of visibility work (work_queue.h).
  WorkQueue& work() { return work_; }
  const WorkQueue& work() const { return work_; }
  // Drops all waiting visibility work and refuses more (a stopping server).
  void abandonWork() { work_.abandon(); }
  // Faces whose bounding box lies within `radius` of the box (sorted).
  FaceList facesWithin(const Box3f& box, float radius) const;
  // Whether an avatar anywhere in view cell `avatarCell` may be visible from
  // any point of view cell `viewerCell` (cell-to-cell visibility, as
  // Funkhouser's RING filtered avatar updates): the avatar cell's box, grown
  // by a body (0.3 m around, 0.2 m above; the avatar stands on a floor within
  // the cell, so not below it), is not hidden
  // by one occluder from the whole viewer cell, the test the PVS applies to
  // objects. Answers are cached (bounded); thread-safe.
  bool cellSeesCell(const glm::ivec3& viewerCell, const glm::ivec3& avatarCell);

  struct CacheStats {
    // pvsComputed: PVS computations of every kind (whole, or of the near
    // faces for a face set), coarse cells included.
    uint64_t hits = 0, misses = 0, pvsComputed = 0, pvsFromDatabase = 0;
    uint64_t cancelled = 0;       // computations dropped unstarted: nobody waited any more
    uint64_t coarseComputed = 0;  // of pvsComputed, coarse cells
    uint64_t dropped = 0;         // prefetch dropped unstarted for the queue's bound
    uint64_t unculled = 0;        // unculled sets computed (no PVS: the workers were behind)
  };
  CacheStats cacheStats() const;
  // From a request to its answer (cached, read or computed): whole PVSs
  // (pvs(): PvsRequest, avatars, HTTP) and cell face sets (cellFaceSet()).
  const LatencyHistogram& pvsLatency() const { return pvsLatency_; }
  const LatencyHistogram& faceSetLatency() const { return faceSetLatency_; }
  bool hasDatabase() const { return database_.has_value(); }

  // ---- impostors (with an impostor database) ------------------------------------
  bool hasImpostors() const { return impostors_.has_value(); }
  // The leader of the view cell holding a cell (cells merged along a
  // street share one record, impostor_database.h); the cell itself when it
  // is its own view cell or was not baked.
  uint32_t impostorViewCell(uint32_t linearCell) const;
  // The impostor record of the cell's view cell (why, its range, and its
  // impostors with the faces they replace), or null when the bake did not
  // visit the cell. Decoded once per view cell and kept (bounded); thread-safe.
  std::shared_ptr<const CellRecord> impostorRecord(uint32_t linearCell) const;
  // What a client drawing the cell's (view cell's) impostors is sent of the face set
  // `faces` (sorted): without the faces the impostors replace, and with the
  // faces of the cell's sites left as geometry, whatever its near-field
  // radius (impostor_placement.h says why). `faces` itself when the cell has
  // neither.
  FaceListPtr withImpostors(uint32_t linearCell, FaceListPtr faces) const;

 private:
  // PVS cache keys: a fine cell's linear index, or kCoarseKey | the linear
  // index of its block's first cell.
  static constexpr uint32_t kCoarseKey = 1u << 31;
  uint32_t pvsKey(const glm::ivec3& cell, CellLevel level) const;
  Box3f pvsKeyBox(uint32_t key) const;
  FaceList computePvs(uint32_t key);
  struct FaceSetKey {
    uint32_t cell;
    uint32_t radiusCm;
    StreamPolicy policy;
    bool operator==(const FaceSetKey&) const = default;
  };
  struct FaceSetKeyHash {
    size_t operator()(const FaceSetKey& k) const {
      return (size_t(k.cell) * 1000003u) ^ (size_t(k.radiusCm) << 1) ^ size_t(k.policy);
    }
  };
  FaceSetKey faceSetKey(const glm::ivec3& cell, CellLevel level, StreamPolicy policy,
                        float radius) const;
  // The visibility face set without a database (see the policies above).
  FaceList computeNearPvs(const FaceSetKey& key, const Box3f& box, const FaceList& near);
  const EpsilonPvs& epsilonPvs();

  Scene scene_;
  ViewCellGrid grid_;
  GroundPlane ground_;
  std::optional<PvsDatabase> database_;
  std::optional<ImpostorDatabase> impostors_;
  struct ImpostorEntry {
    std::shared_ptr<const CellRecord> record;
    FaceListPtr replaced;
  };
  mutable std::mutex impostorMutex_;
  mutable std::unordered_map<uint32_t, ImpostorEntry> impostorCells_;  // decoded records (bounded)
  ImpostorEntry impostorEntry(uint32_t linearCell) const;
  static constexpr size_t kImpostorCellsKept = 64;
  WorkQueue work_;  // before the caches, which submit to it
  LatencyHistogram pvsLatency_, faceSetLatency_;
  std::unique_ptr<CullingScene> culling_;
  std::once_flag pvsOnce_;
  std::unique_ptr<StaticWorld> statics_;     // without a database: for the horizons
  std::unique_ptr<HorizonFusion> horizons_;  // may be null
  std::unique_ptr<EpsilonPvs> pvs_;
  std::vector<wire::FaceTriangles> faces_;
  std::optional<Backdrop> backdrop_;
  std::vector<Box3f> faceBoxes_;
  // Faces by X/Z cell of their bounding boxes (no cells for an empty scene).
  XzGrid faceGrid_;
  std::unique_ptr<AsyncCache<uint32_t, FaceList>> pvsCache_;
  std::unique_ptr<AsyncCache<FaceSetKey, FaceList, FaceSetKeyHash>> faceSetCache_;
  std::atomic<uint64_t> pvsFromDatabase_{0}, coarseComputed_{0}, nearPvsComputed_{0},
      unculledComputed_{0};
  std::once_flag databaseFailureLogged_;
  std::mutex cellPairsMutex_;
  std::unordered_map<uint64_t, bool> cellPairs_;
};

}  // namespace vistream
