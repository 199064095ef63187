#include "server/stream/stream_scheduler.h"

#include <algorithm>
#include <cmath>
#include <iterator>

namespace vistream {

StreamScheduler::StreamScheduler(const StreamWorld& world, StreamSchedulerConfig config,
                                 float radius, uint64_t budgetBytes)
    : world_(world), config_(config), radius_(radius), budget_(budgetBytes) {
  held_.assign((size_t(world_.faceCount()) + 63) / 64, 0);
}

void StreamScheduler::setPose(const glm::dvec3& position, const glm::vec3& velocity, float yawDeg,
                              float pitchDeg) {
  position_ = position;
  velocity_ = velocity;
  yaw_ = yawDeg;
  pitch_ = pitchDeg;
  const auto cell = world_.cellOf(glm::vec3(position_));
  hasPose_ = cell.has_value();
  if (cell) cell_ = *cell;
  if (hasPose_) updateNeededCells();
}

bool StreamScheduler::isNeeded(uint32_t cell) const {
  return std::find(needed_.begin(), needed_.end(), cell) != needed_.end();
}

void StreamScheduler::setHeld(uint32_t face, bool on) {
  uint64_t& word = held_[face >> 6];
  const uint64_t bit = uint64_t(1) << (face & 63);
  if (bool(word & bit) == on) return;
  word ^= bit;
  if (on) {
    heldBytes_ += world_.faceBytes(face);
    ++heldCount_;
    evictionsExhausted_ = false;
  } else {
    heldBytes_ -= world_.faceBytes(face);
    --heldCount_;
  }
}

void StreamScheduler::markHeld(std::span<const uint32_t> faces) {
  for (const uint32_t f : faces) setHeld(f, true);
}

void StreamScheduler::updateNeededCells() {
  const ViewCellGrid& grid = world_.grid();
  std::vector<uint32_t> needed{uint32_t(grid.linearIndex(cell_))};
  std::vector<double> inS{0.0};
  auto add = [&](const glm::ivec3& c, double seconds) {
    if (!grid.contains(c)) return;
    const uint32_t l = uint32_t(grid.linearIndex(c));
    if (std::find(needed.begin(), needed.end(), l) == needed.end()) {
      needed.push_back(l);
      inS.push_back(seconds);
    }
  };
  // Ahead along the velocity: at most kMaxPrefetchSteps samples, spaced
  // half a cell or more, whatever the speed.
  const float speed = float(std::min(double(glm::length(velocity_)), config_.maxSpeedMps));
  if (speed > 1e-3f) {
    // Never farther than across the whole grid.
    const double gridDiagonal = glm::length(glm::dvec3(grid.cellSize()) * glm::dvec3(grid.dims()));
    const double horizon = std::min(config_.prefetchSeconds * speed, gridDiagonal);
    const double step =
        std::max(0.5 * std::min(grid.cellSize().x, grid.cellSize().z), horizon / kMaxPrefetchSteps);
    const glm::vec3 direction = glm::normalize(velocity_);
    for (int i = 1; i <= kMaxPrefetchSteps && double(i) * step <= horizon; ++i)
      if (auto c = world_.cellOf(glm::vec3(position_) + direction * float(double(i) * step)))
        add(*c, double(i) * step / double(speed));
  }
  // Neighbours the client could step into before their face sets would
  // arrive: those whose shared side or corner it could reach within
  // neighbourLeadS at its speed (at least walking speed: it may turn).
  // Farther ones would ship their PVS long before need, mostly for nothing.
  const Box3f box = grid.cellBox(cell_);
  const glm::vec3 p(position_);
  const float walking = std::max(speed, 1.4f);
  const float margin = float(config_.neighbourLeadS) * walking;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dx = -1; dx <= 1; ++dx) {
      const float gapX = dx == 0 ? 0.0f : dx < 0 ? p.x - box.lo.x : box.hi.x - p.x;
      const float gapZ = dz == 0 ? 0.0f : dz < 0 ? p.z - box.lo.z : box.hi.z - p.z;
      if (gapX <= margin && gapZ <= margin)
        add(cell_ + glm::ivec3(dx, 0, dz), double(std::max({gapX, gapZ, 0.0f}) / walking));
    }
  // The cell the client has just left is no longer worth its current-cell
  // urgency: its requests are dropped (joined ones for the same coarse cell
  // live on through the new current cell's request), and asked for again
  // as prefetch if it is still needed.
  if (!needed_.empty() && needed_.front() != needed.front())
    for (CellLevel level : {CellLevel::Fine, CellLevel::Coarse, CellLevel::Unculled})
      requested_.erase(requestKey(needed_.front(), level));
  needed_ = std::move(needed);
  neededInS_ = std::move(inS);
  evictionsExhausted_ = false;  // the faces to keep may have changed
  // Forget the face sets of cells no longer needed (their faces stay held),
  // and drop their requests: the newest pose wins.
  for (auto it = cellSets_.begin(); it != cellSets_.end();) {
    if (isNeeded(it->first)) {
      ++it;
    } else {
      cursor_.erase(it->first);
      levels_.erase(it->first);
      it = cellSets_.erase(it);
    }
  }
  for (auto it = requested_.begin(); it != requested_.end();)
    it = isNeeded(uint32_t(it->first)) ? std::next(it) : requested_.erase(it);
  for (auto it = retryAt_.begin(); it != retryAt_.end();)
    it = isNeeded(uint32_t(it->first)) ? std::next(it) : retryAt_.erase(it);
}

std::vector<StreamScheduler::CellRequest> StreamScheduler::takeCellRequests(double nowS) {
  std::vector<CellRequest> out;
  if (!hasPose_) return out;
  auto request = [&](uint32_t l, CellLevel level, WorkPriority priority) {
    const uint64_t key = requestKey(l, level);
    if (auto r = retryAt_.find(key); r != retryAt_.end()) {
      if (nowS < r->second) return;
      retryAt_.erase(r);
    }
    Interest interest = makeInterest();
    requested_[key] = interest;
    out.push_back({l, std::move(interest), level, priority});
  };
  // Requests of one level for a cell; the other level's may also be out.
  auto requestedAny = [&](uint32_t l) {
    return requested_.count(requestKey(l, CellLevel::Fine)) ||
           requested_.count(requestKey(l, CellLevel::Coarse)) ||
           requested_.count(requestKey(l, CellLevel::Unculled));
  };
  // Unculled sets stand in for PVSs the workers cannot deliver in time.
  const bool mayUncull = config_.coarseFirst && config_.policy == StreamPolicy::Visibility;
  // A client keeps its place in the line: the current cell is due from when
  // the client began waiting for one, so a client walking into the next
  // cell before its request ran is not sent to the back of the queue.
  if (needed_.empty() || cellSets_.count(needed_.front()))
    waitingSinceS_.reset();
  else if (!waitingSinceS_)
    waitingSinceS_ = nowS;
  size_t outstanding = 0;  // of needed cells' first face sets (refinement apart)
  for (const auto& [key, interest] : requested_)
    if (!cellSets_.count(uint32_t(key))) ++outstanding;
  for (size_t i = 0; i < needed_.size(); ++i) {
    const uint32_t l = needed_[i];
    // The limit is on prefetch: the current cell is always asked for.
    if (i > 0 && outstanding >= config_.maxCellRequests) break;
    // Prefetch backs off while the workers are behind.
    if (i > 0 && behind_) break;
    if (cellSets_.count(l) || requestedAny(l)) continue;
    WorkPriority priority = i == 0
                                ? WorkPriority{WorkPriority::Current, waitingSinceS_.value_or(nowS)}
                                : WorkPriority{WorkPriority::Prefetch, nowS + neededInS_[i]};
    // Coarse first unless the cell's own set is at hand (or is all there
    // is); for the current cell, unculled if neither is cached and current
    // cells are lagging.
    const glm::ivec3 c = world_.grid().cellAt(l);
    CellLevel level = CellLevel::Fine;
    if (config_.coarseFirst && config_.policy == StreamPolicy::Visibility &&
        !world_.hasCellFaceSet(c, CellLevel::Fine, config_.policy, radius_)) {
      level = CellLevel::Coarse;
      if (mayUncull && i == 0 && lagging_ &&
          !world_.hasCellFaceSet(c, CellLevel::Coarse, config_.policy, radius_)) {
        level = CellLevel::Unculled;
        priority.rank = WorkPriority::Immediate;
      }
    }
    request(l, level, priority);
    ++outstanding;
  }
  // A current cell waited for too long: its unculled set as well.
  if (mayUncull && !needed_.empty() && waitingSinceS_ &&
      nowS - *waitingSinceS_ >= config_.unculledAfterS &&
      !requested_.count(requestKey(needed_.front(), CellLevel::Unculled)))
    request(needed_.front(), CellLevel::Unculled, {WorkPriority::Immediate, nowS});
  // Refinement: the current cell's own set once its coarse one streams,
  // the coarse one once its unculled one does.
  if (config_.coarseFirst && !behind_ && !needed_.empty()) {
    const uint32_t l = needed_.front();
    const std::optional<CellLevel> loaded = loadedLevel(l);
    if (loaded && *loaded != CellLevel::Fine && !requested_.count(requestKey(l, CellLevel::Fine)) &&
        !requested_.count(requestKey(l, CellLevel::Coarse)))
      request(l, *loaded == CellLevel::Unculled ? CellLevel::Coarse : CellLevel::Fine,
              {WorkPriority::Refine, nowS});
  }
  return out;
}

bool StreamScheduler::onFaceSet(uint32_t cell, FaceListPtr faces, CellLevel level) {
  // A result nobody asks for any more (cancelled, or answered already
  // through a request that joined the same computation).
  if (requested_.erase(requestKey(cell, level)) == 0 || !faces || !isNeeded(cell)) return false;
  // Levels from the tightest: Fine, Coarse, Unculled. A set no tighter than
  // the loaded one is moot (refined already).
  const std::optional<CellLevel> loaded = loadedLevel(cell);
  if (loaded && uint8_t(level) >= uint8_t(*loaded)) return false;
  // A tighter set replaces a looser one; looser requests still out are moot.
  for (CellLevel looser : {CellLevel::Coarse, CellLevel::Unculled})
    if (uint8_t(looser) > uint8_t(level)) requested_.erase(requestKey(cell, looser));
  levels_[cell] = level;
  // Impostors stand in for the far faces they replace; sites left as
  // geometry come as faces (StreamWorld::withImpostors).
  if (config_.impostors) faces = world_.withImpostors(cell, std::move(faces));
  // Announced ready with a looser set: the client held a superset. Should
  // the budget have kept some of the tighter set back, the cell is announced
  // again once whole.
  if (announced_.count(cell) &&
      !std::all_of(faces->begin(), faces->end(), [&](uint32_t f) { return held(f); }))
    announced_.erase(cell);
  cellSets_[cell] = std::move(faces);
  cursor_[cell] = 0;
  evictionsExhausted_ = false;
  return true;
}

void StreamScheduler::onDropped(uint32_t cell, CellLevel level, double nowS) {
  const uint64_t key = requestKey(cell, level);
  if (requested_.erase(key) == 0 || !isNeeded(cell)) return;
  retryAt_[key] = nowS + kRetryAfterDropS;
}

std::optional<StreamScheduler::CullRequest> StreamScheduler::takeCullRequest(double nowS) {
  if (config_.policy != StreamPolicy::Visibility || needed_.empty()) return std::nullopt;
  const auto it = cellSets_.find(needed_.front());
  if (it == cellSets_.end() || cursor_[it->first] >= it->second->size())
    return std::nullopt;  // not loaded, or complete
  // A new current cell is culled at once; the same cell again at most every cullIntervalS.
  if (culledCell_ == it->first && nowS - lastCullS_ < config_.cullIntervalS) return std::nullopt;
  lastCullS_ = nowS;
  culledCell_ = it->first;
  return CullRequest{it->first, position_, yaw_, pitch_, it->second};
}

void StreamScheduler::onCulled(uint32_t cell, FaceList visible) {
  visibleNow_ = std::move(visible);
  visibleNowCell_ = cell;
}

bool StreamScheduler::readyToStream(bool cullingInFlight) const {
  if (!hasPose_ || needed_.empty() || !cellSets_.count(needed_.front())) return false;
  return !(config_.policy == StreamPolicy::Visibility && visibleNowCell_ != needed_.front() &&
           cullingInFlight);
}

std::vector<uint32_t> StreamScheduler::takeEvictions() {
  std::vector<uint32_t> evicted;
  // The budget is the client's number: thresholds without overflow, and no
  // scan again until something held or needed changed since a fruitless one.
  if (budget_ == 0 || heldBytes_ <= budget_ / 10 * 9 || evictionsExhausted_) return evicted;
  const uint64_t target = budget_ / 10 * 7;
  // Keep what the needed cells stream; evict the rest, farthest first.
  std::vector<uint8_t> keep(world_.faceCount(), 0);
  for (const auto& [l, set] : cellSets_)
    for (uint32_t f : *set) keep[f] = 1;
  std::vector<std::pair<float, uint32_t>> candidates;
  for (size_t w = 0; w < held_.size(); ++w)
    for (uint64_t bits = held_[w]; bits; bits &= bits - 1) {
      const uint32_t f = uint32_t(w * 64 + size_t(__builtin_ctzll(bits)));
      if (!keep[f])
        candidates.emplace_back(glm::length(world_.faceCentre(f) - glm::vec3(position_)), f);
    }
  std::sort(candidates.begin(), candidates.end(), std::greater<>());
  for (const auto& [d, f] : candidates) {
    if (heldBytes_ <= target) break;
    setHeld(f, false);
    evicted.push_back(f);
  }
  evictionsExhausted_ = evicted.empty();
  std::sort(evicted.begin(), evicted.end());
  // Cells announced ready may have lost faces: they are announced again when whole.
  for (auto it = announced_.begin(); it != announced_.end();)
    it = cellSets_.count(*it) ? std::next(it) : announced_.erase(it);
  return evicted;
}

bool StreamScheduler::worthABatch() const {
  if (config_.coalesceBytes == 0 || needed_.empty()) return true;
  // Faces in view from the pose are due at once.
  if (visibleNowCell_ == needed_.front())
    for (uint32_t f : visibleNow_)
      if (!held(f)) return true;
  size_t pending = 0;
  for (size_t i = 0; i < needed_.size(); ++i) {
    const auto it = cellSets_.find(needed_[i]);
    if (it == cellSets_.end()) continue;
    const FaceList& set = *it->second;
    const auto c = cursor_.find(needed_[i]);
    for (size_t k = c == cursor_.end() ? 0 : c->second; k < set.size(); ++k) {
      if (held(set[k])) continue;
      // A cell the client is in, or may reach soon, goes now.
      if (i == 0 || neededInS_[i] <= config_.coalesceUntilS) return true;
      pending += world_.faceBytes(set[k]);
      if (pending >= config_.coalesceBytes) return true;
    }
  }
  return false;
}

std::vector<uint32_t> StreamScheduler::takeBatch() {
  std::vector<uint32_t> batch;
  if (!worthABatch()) return batch;
  size_t bytes = 0;
  auto take = [&](uint32_t f) {
    if (held(f) || (budget_ > 0 && heldBytes_ + world_.faceBytes(f) > budget_)) return;
    setHeld(f, true);
    batch.push_back(f);
    bytes += world_.faceBytes(f);
  };
  // Faces in view first, while the culling is of the cell the client is in.
  if (!needed_.empty() && visibleNowCell_ == needed_.front()) {
    for (uint32_t f : visibleNow_) {
      if (bytes >= config_.batchBytes) break;
      take(f);
    }
  }
  for (uint32_t l : needed_) {
    auto it = cellSets_.find(l);
    if (it == cellSets_.end()) continue;
    const FaceList& set = *it->second;
    size_t& c = cursor_[l];
    while (c < set.size() && bytes < config_.batchBytes) {
      take(set[c]);
      if (!held(set[c])) break;  // over budget: this cell cannot complete for now
      ++c;
    }
    if (bytes >= config_.batchBytes) break;
  }
  return batch;
}

std::vector<StreamScheduler::ReadyCell> StreamScheduler::takeReadyCells() {
  std::vector<ReadyCell> out;
  for (uint32_t l : needed_) {
    auto it = cellSets_.find(l);
    if (it == cellSets_.end() || announced_.count(l)) continue;
    size_t& c = cursor_[l];
    while (c < it->second->size() && held((*it->second)[c])) ++c;
    if (c < it->second->size()) continue;
    announced_.insert(l);
    out.push_back({world_.grid().cellAt(l), uint32_t(it->second->size())});
  }
  return out;
}

}  // namespace vistream
