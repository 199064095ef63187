// What the streaming server shares between all sessions: the scene, its view
// cell grid, per-face geometry ready to encode, the PVS of each cell
// (from a baked database or computed on demand, each once, in a bounded LRU
// cache) and the face set each cell streams under each policy.
//
// Policies: "visibility" streams, per cell, the faces of the cell's PVS
// within the near-field radius of the cell; "radius" (the baseline) streams
// every face within that radius, visible or not.
//
// Thread safety: immutable after construction except the caches, which are
// thread-safe; every const member may be called from any thread. Work that
// computes (PVS, face sets) runs on the executor passed in, never inline.
#pragma once

#include <boost/asio/thread_pool.hpp>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/scene/scene.h"
#include "common/spatial/xz_grid.h"
#include "common/world/static_world.h"
#include "protocol/geometry/geometry_codec.h"
#include "server/stream/async_cache.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/hierarchical_culling.h"
#include "server/visibility/pvs_database.h"
#include "server/visibility/view_cell_grid.h"

namespace vistream {

enum class StreamPolicy : uint8_t { Visibility, Radius };
StreamPolicy parseStreamPolicy(const std::string& name);  // throws InputError
const char* streamPolicyName(StreamPolicy p);

struct StreamWorldOptions {
  std::filesystem::path pvsDatabase;  // empty: compute every PVS on demand
  float cellSize = 4.0f;              // without a database (metres), the paper's scale
  GroundChoice ground;  // without a database: the free space's ground (static_world.h)
  size_t pvsCacheCells = 4096;
  size_t faceSetCacheEntries = 4096;
  // Memory bounds of the two caches (face IDs at 4 bytes each). Clients pick
  // part of a face set's key (their radius), so entries alone do not bound it.
  size_t pvsCacheBytes = size_t(1) << 30;
  size_t faceSetCacheBytes = size_t(1) << 30;
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
  // What a client holding the face stores: its decoded triangles and ID.
  uint32_t faceBytes(uint32_t id) const {
    return uint32_t(faces_[id].corners.size() * sizeof(glm::vec3) + 8);
  }
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
    uint64_t hits = 0, misses = 0, pvsComputed = 0, pvsFromDatabase = 0;
    uint64_t cancelled = 0;  // computations dropped unstarted: nobody waited any more
  };
  CacheStats cacheStats() const;
  bool hasDatabase() const { return database_.has_value(); }

 private:
  FaceList computePvs(uint32_t linear);
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
  const EpsilonPvs& epsilonPvs();

  Scene scene_;
  ViewCellGrid grid_;
  GroundPlane ground_;
  std::optional<PvsDatabase> database_;
  std::unique_ptr<CullingScene> culling_;
  std::once_flag pvsOnce_;
  std::unique_ptr<EpsilonPvs> pvs_;
  std::vector<wire::FaceTriangles> faces_;
  std::vector<Box3f> faceBoxes_;
  // Faces by X/Z cell of their bounding boxes (no cells for an empty scene).
  XzGrid faceGrid_;
  std::unique_ptr<AsyncCache<uint32_t, FaceList>> pvsCache_;
  std::unique_ptr<AsyncCache<FaceSetKey, FaceList, FaceSetKeyHash>> faceSetCache_;
  std::atomic<uint64_t> pvsFromDatabase_{0};
  std::once_flag databaseFailureLogged_;
  std::mutex cellPairsMutex_;
  std::unordered_map<uint64_t, bool> cellPairs_;
};

}  // namespace vistream
