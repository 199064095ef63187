// What one client gets next: the streaming policy of a session, apart from
// its socket. The session (session.h) feeds it the client's pose and the
// results of the visibility work it asks for, and sends what it emits; the
// scheduler itself does no I/O, starts no threads and reads no clock (times
// are passed in), so it is tested by feeding it poses and budgets.
//
// The policy:
// - Cells needed: the current view cell first, then the cells ahead along the
//   velocity (prefetchSeconds of travel, sampled at most kMaxPrefetchSteps
//   times), then the neighbours whose shared side or corner the client
//   could reach within neighbourLeadS (at its speed, at least walking speed).
//   Each needed cell has a time to reach (0 for the current one).
// - Face sets of needed cells are requested in that order, at most
//   maxCellRequests outstanding (the current cell is asked for whatever is
//   outstanding); a cell no longer needed, or no longer the current one,
//   has its request dropped (its Interest expires, so queued work for it is
//   cancelled unless another request joined it).
//   Each request says how urgent it is (work_queue.h): the current cell is
//   rank Current, due now; a prefetch cell is rank Prefetch, due when the
//   client is expected to reach it; a client waiting for its current cell
//   keeps its place (due from when it began waiting) across cell changes.
//   While the workers are behind
//   (setBehind), only the current cell is requested: prefetch backs off.
//   A prefetch request the work queue dropped (onDropped) is asked again no
//   sooner than kRetryAfterDropS later.
// - Coarse first (config.coarseFirst, the server without a database): a
//   needed cell whose own face set is not cached gets its coarse parent's
//   (stream_world.h), a superset, at once; the current cell's own face set
//   is then requested as a refinement (rank Refine, not while behind) and
//   replaces the coarse one when it arrives. The client already holds every
//   face of the refined set unless the budget stopped some (they are sent
//   then); what the coarse set had beyond it is not evicted at once but is
//   no longer kept by that cell when the budget needs room.
// - Unculled before that, when waiting would cost (coarse first only, under
//   the visibility policy): while current cells wait longer than the lag
//   bound (setLagging), a current cell with neither set cached gets its
//   block's unculled set (every face within the radius, a grid query: rank
//   Immediate), so the client is served whatever the load; so does a
//   current cell whose set has not come within unculledAfterS of the client
//   beginning to wait. Prefetch never gets one: an unculled set costs the
//   bytes of the radius policy, and a start-up crowd that is briefly behind
//   would take them all. The
//   current cell then refines to the coarse set and then to its own (rank
//   Refine), each replacing the looser one as above. A set looser than the
//   one loaded is ignored.
// - Under the visibility policy nothing streams before the current cell's
//   face set is known and its culling (faces visible from the pose) has
//   answered; those faces go first, then the rest of each needed cell in
//   order. A new current cell is culled at once, the same cell again at most
//   every cullIntervalS.
// - Memory budget: a face that would take the client over its budget is not
//   sent; above 90% of the budget, faces outside every needed cell are
//   evicted, farthest first, down to 70%.
// - Impostors (config.impostors): a cell's face set leaves out the faces its
//   impostors replace (StreamWorld::replacedFaces); the session sends the
//   impostors themselves (session.h).
// - CellReady once the client holds every face of a needed cell (again after
//   an eviction took some of them).
// - Coalescing (coalesceBytes > 0): a small batch waits while nothing in it
//   is due: no face in view from the pose or of the current cell, and no
//   needed cell the client may reach within coalesceUntilS; faces of cells
//   farther ahead gather until they fill coalesceBytes, since a frame's
//   fixed cost (about 50 bytes plus the codec's) weighs on small batches.
//   A cell is never announced before all its faces were sent.
//
// Not thread-safe: one scheduler per session, used on the session's strand.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <vector>

#include "server/stream/stream_world.h"

namespace vistream {

struct StreamSchedulerConfig {
  StreamPolicy policy = StreamPolicy::Visibility;
  double prefetchSeconds = 3.0;
  double maxSpeedMps = 100.0;  // speeds above are clamped (the session refuses them anyway)
  unsigned maxCellRequests = 3;
  size_t batchBytes = 48u << 10;  // raw face bytes per batch
  double cullIntervalS = 0.25;
  // Neighbour prefetch: seconds of travel to the shared side or corner. One
  // second covers a face set from the cache and its batch with room to
  // spare (city1, 40 walkers: 0 misses); 3 s (the previous margin) took in
  // all eight neighbours of a 4 m cell at walking speed.
  double neighbourLeadS = 1.0;
  // Coalescing (see above); 0 bytes: every batch goes as soon as it can.
  size_t coalesceBytes = 0;
  double coalesceUntilS = 1.5;
  bool coarseFirst = false;  // see above; the server sets it without a database
  // Coarse first: seconds a client waits for its current cell's set before
  // it gets the unculled set (see above). Above a coarse PVS's cost on
  // bigcity (0.15-0.35 s on one core, 20 clients), so a client alone gets
  // the PVS rather than the larger unculled set.
  double unculledAfterS = 0.75;
  // The client draws the impostors of its cells (StreamWorld::hasImpostors):
  // a cell's face set leaves out the faces its impostors replace.
  bool impostors = false;
};

class StreamScheduler {
 public:
  // Samples along the velocity when prefetching: bounds the work of one pose
  // whatever the speed and horizon.
  static constexpr int kMaxPrefetchSteps = 32;
  // Seconds before a prefetch request the work queue dropped is made again.
  static constexpr double kRetryAfterDropS = 1.0;

  // `radius`: the client's near-field radius (metres); `budgetBytes`: its
  // memory budget (0: unlimited), counted in StreamWorld::faceBytes.
  StreamScheduler(const StreamWorld& world, StreamSchedulerConfig config, float radius,
                  uint64_t budgetBytes);

  // A new pose (local frame; checked for plausibility by the caller).
  void setPose(const glm::dvec3& position, const glm::vec3& velocity, float yawDeg, float pitchDeg);
  bool hasPose() const { return hasPose_; }
  float radius() const { return radius_; }  // the client's near-field radius (metres)
  const std::vector<uint32_t>& neededCells() const {
    return needed_;
  }  // linear indices, current first

  // ---- visibility work ---------------------------------------------------------
  struct CellRequest {
    uint32_t cell;  // linear index
    Interest
        interest;  // hand to StreamWorld::cellFaceSet; expires when the cell is no longer wanted
    CellLevel level = CellLevel::Fine;
    WorkPriority priority;  // dueS on the clock of `nowS`
  };
  // The face sets to request now (marked as requested). `nowS`: the caller's
  // clock, for due times and retries.
  std::vector<CellRequest> takeCellRequests(double nowS = 0.0);
  // A requested face set arrived. False if it was no longer wanted (dropped).
  bool onFaceSet(uint32_t cell, FaceListPtr faces, CellLevel level = CellLevel::Fine);
  // The work queue dropped a request (prefetch or refinement only).
  void onDropped(uint32_t cell, CellLevel level, double nowS);
  bool isRequested(uint32_t cell, CellLevel level = CellLevel::Fine) const {
    return requested_.count(requestKey(cell, level)) > 0;
  }
  // Whether the needed cell streams its own (fine) face set rather than its
  // coarse parent's; false while it has none.
  bool hasFineSet(uint32_t cell) const { return loadedLevel(cell) == CellLevel::Fine; }
  // The level of the set a needed cell streams, if it has one.
  std::optional<CellLevel> loadedLevel(uint32_t cell) const {
    const auto it = levels_.find(cell);
    return it == levels_.end() ? std::nullopt : std::optional<CellLevel>(it->second);
  }
  // The workers are behind (WorkQueue::behind): prefetch and refinement wait.
  void setBehind(bool behind) { behind_ = behind; }
  // Current cells wait longer than the lag bound: unculled sets stand in.
  void setLagging(bool lagging) { lagging_ = lagging; }

  struct CullRequest {
    uint32_t cell;
    glm::dvec3 eye;
    float yawDeg, pitchDeg;
    FaceListPtr faceSet;  // intersect the culling's faces with this
  };
  // The culling to start now, if one is due (visibility policy only); the
  // caller runs at most one at a time and reports it with onCulled.
  std::optional<CullRequest> takeCullRequest(double nowS);
  void onCulled(uint32_t cell, FaceList visible);

  // Drops every request (a closing session): their interests expire.
  void cancelAll() { requested_.clear(); }
  size_t outstandingRequests() const { return requested_.size(); }

  // ---- what to send ------------------------------------------------------------
  // Whether streaming may go on: the current cell's face set is known and,
  // under the visibility policy, not waiting for its first culling.
  bool readyToStream(bool cullingInFlight) const;
  // Faces to evict now (sorted; empty if within the budget).
  std::vector<uint32_t> takeEvictions();
  // The next batch of faces to send, in order (about batchBytes); marks them
  // held. Empty while coalescing holds a small batch back (see above).
  std::vector<uint32_t> takeBatch();
  // Whether a batch would go now: something is due, or enough has gathered.
  bool worthABatch() const;
  struct ReadyCell {
    glm::ivec3 cell;
    uint32_t faces;
  };
  // Needed cells the client now holds whole, not announced before.
  std::vector<ReadyCell> takeReadyCells();

  // The client already holds these faces (a Hello after a reconnect names
  // what it kept from an earlier session): none of them is sent again. IDs
  // must be below the scene's face count. Beyond the memory budget,
  // takeEvictions() evicts as for faces sent.
  void markHeld(std::span<const uint32_t> faces);
  bool held(uint32_t face) const { return (held_[face >> 6] >> (face & 63)) & 1u; }
  uint32_t heldCount() const { return heldCount_; }
  uint64_t heldBytes() const { return heldBytes_; }
  uint32_t cellsReady() const { return uint32_t(announced_.size()); }

 private:
  static uint64_t requestKey(uint32_t cell, CellLevel level) {
    return (uint64_t(level) << 32) | cell;
  }
  void updateNeededCells();
  void setHeld(uint32_t face, bool on);
  bool isNeeded(uint32_t cell) const;

  const StreamWorld& world_;
  const StreamSchedulerConfig config_;
  const float radius_;
  const uint64_t budget_;

  bool hasPose_ = false;
  glm::dvec3 position_{0.0};
  glm::vec3 velocity_{0.0f};
  float yaw_ = 0.0f, pitch_ = 0.0f;
  glm::ivec3 cell_{0};

  std::vector<uint64_t> held_;  // a bitset over face IDs
  uint64_t heldBytes_ = 0;
  uint32_t heldCount_ = 0;
  std::vector<uint32_t> needed_;              // linear cell indices, current first
  std::vector<double> neededInS_;             // per needed cell: seconds until the client needs it
  std::map<uint32_t, FaceListPtr> cellSets_;  // loaded face sets of needed cells
  std::map<uint32_t, size_t> cursor_;         // per loaded cell: faces before this index are held
  std::map<uint32_t, CellLevel> levels_;      // per loaded cell: the level of its set
  std::map<uint64_t, Interest> requested_;    // face sets being computed, by requestKey
  std::map<uint64_t, double> retryAt_;        // dropped requests: not again before this time
  bool behind_ = false;
  bool lagging_ = false;
  std::optional<double> waitingSinceS_;  // since when the current cell has had no face set
  std::set<uint32_t> announced_;
  FaceList visibleNow_;
  uint32_t culledCell_ = UINT32_MAX, visibleNowCell_ = UINT32_MAX;
  double lastCullS_ = -1e300;
  bool evictionsExhausted_ = false;  // the last scan found nothing to evict; nothing changed since
};

}  // namespace vistream
