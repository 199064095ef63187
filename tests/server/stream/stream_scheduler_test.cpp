// The streaming policy without sockets: poses and budgets in, requests and
// batches out, checked against the world's own face sets and a brute-force
// replay of what the client holds.
#include "server/stream/stream_scheduler.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <future>
#include <limits>
#include <set>

#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

// The street scene's world, and face sets computed on request, in full.
class SchedulerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { world_ = new StreamWorld(streetScene(), StreamWorldOptions{}); }
  static void TearDownTestSuite() {
    delete world_;
    world_ = nullptr;
  }

  StreamWorld& world() { return *world_; }
  FaceListPtr faceSet(uint32_t cell, StreamPolicy policy = StreamPolicy::Visibility,
                      float radius = 200.0f) {
    std::promise<FaceListPtr> p;
    world_->cellFaceSet(world_->grid().cellAt(cell), policy, radius, pool_,
                        [&](FaceListPtr f) { p.set_value(f); });
    return p.get_future().get();
  }
  // Answers every pending request of the scheduler with the world's face sets.
  void answerRequests(StreamScheduler& s, StreamPolicy policy = StreamPolicy::Visibility) {
    for (auto& r : s.takeCellRequests()) s.onFaceSet(r.cell, faceSet(r.cell, policy));
  }
  uint32_t cellOf(const glm::dvec3& p) {
    return uint32_t(world_->grid().linearIndex(*world_->cellOf(glm::vec3(p))));
  }

  static StreamWorld* world_;
  boost::asio::thread_pool pool_{2};
};
StreamWorld* SchedulerTest::world_ = nullptr;

const glm::dvec3 kPoint{0.0, 1.7, 8.0};

TEST_F(SchedulerTest, AsksForTheCurrentCellFirstAndNeverMoreThanTheRequestLimit) {
  StreamSchedulerConfig cfg;
  cfg.maxCellRequests = 2;
  cfg.neighbourLeadS = 3.0;  // every neighbour needed: more cells than the limit
  StreamScheduler s(world(), cfg, 200.0f, 0);
  EXPECT_TRUE(s.takeCellRequests().empty()) << "nothing before a pose";
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  const auto first = s.takeCellRequests();
  ASSERT_EQ(first.size(), 2u);
  EXPECT_EQ(first[0].cell, cellOf(kPoint));
  EXPECT_TRUE(s.takeCellRequests().empty()) << "two are outstanding";
  s.onFaceSet(first[0].cell, faceSet(first[0].cell));
  const auto next = s.takeCellRequests();
  ASSERT_EQ(next.size(), 1u) << "one slot freed";
  EXPECT_NE(next[0].cell, first[1].cell);
}

TEST_F(SchedulerTest, MovingAwayCancelsRequestsForCellsNoLongerNeeded) {
  StreamScheduler s(world(), {}, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  auto requests = s.takeCellRequests();
  ASSERT_FALSE(requests.empty());
  std::vector<std::weak_ptr<const int>> interests;
  for (auto& r : requests) interests.push_back(r.interest);
  requests.clear();  // the world would hold them only weakly
  s.setPose({-24.0, 1.7, -24.0}, glm::vec3(0.0f), 0.0f, 0.0f);  // another corner of the street
  for (auto& w : interests) EXPECT_TRUE(w.expired());
  // A late answer for a dropped cell is ignored.
  EXPECT_FALSE(s.onFaceSet(cellOf(kPoint), faceSet(cellOf(kPoint))));
  EXPECT_EQ(s.takeCellRequests().front().cell, cellOf({-24.0, 1.7, -24.0}));
}

TEST_F(SchedulerTest, NothingStreamsBeforeTheCurrentCellIsKnownAndItsCullingHasAnswered) {
  StreamScheduler s(world(), {}, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  EXPECT_FALSE(s.readyToStream(false));
  answerRequests(s);
  const auto cull = s.takeCullRequest(0.0);
  ASSERT_TRUE(cull);
  EXPECT_EQ(cull->cell, cellOf(kPoint));
  EXPECT_FALSE(s.readyToStream(true)) << "the first culling of the cell is in flight";
  // The same cell is culled again only after the interval.
  EXPECT_FALSE(s.takeCullRequest(0.1));
  s.onCulled(cull->cell, {});
  EXPECT_TRUE(s.readyToStream(false));
  EXPECT_TRUE(s.takeCullRequest(0.3));
}

TEST_F(SchedulerTest, FacesInViewGoFirstThenEveryFaceOfTheCellOnceThenCellReady) {
  StreamScheduler s(world(), {}, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  answerRequests(s);
  const auto cull = s.takeCullRequest(0.0);
  ASSERT_TRUE(cull);
  // Say the viewer sees the cell's last three faces.
  const FaceList& set = *cull->faceSet;
  ASSERT_GE(set.size(), 4u);
  const FaceList visible(set.end() - 3, set.end());
  s.onCulled(cull->cell, visible);
  std::vector<uint32_t> sent;
  while (true) {
    auto batch = s.takeBatch();
    if (batch.empty()) break;
    sent.insert(sent.end(), batch.begin(), batch.end());
  }
  ASSERT_GE(sent.size(), 3u);
  EXPECT_EQ(FaceList(sent.begin(), sent.begin() + 3), visible);
  std::set<uint32_t> unique(sent.begin(), sent.end());
  EXPECT_EQ(unique.size(), sent.size()) << "a face was sent twice";
  for (uint32_t f : set)
    EXPECT_TRUE(unique.count(f)) << "face " << f << " of the current cell never sent";
  const auto ready = s.takeReadyCells();
  ASSERT_FALSE(ready.empty());
  EXPECT_EQ(uint32_t(world().grid().linearIndex(ready.front().cell)), cellOf(kPoint));
  EXPECT_EQ(ready.front().faces, set.size());
  EXPECT_TRUE(s.takeReadyCells().empty()) << "announced once";
}

TEST_F(SchedulerTest, ABudgetIsNeverExceededAndEvictionsTakeTheFarthestFacesNotNeeded) {
  // Enough for one corner's cells, not for two.
  StreamScheduler probe(world(), {}, 200.0f, 0);
  probe.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  answerRequests(probe);
  while (!probe.takeBatch().empty()) answerRequests(probe);
  const uint64_t budget = probe.heldBytes() + probe.heldBytes() / 4;

  StreamScheduler s(world(), {}, 200.0f, budget);
  auto drain = [&] {
    for (int round = 0; round < 100; ++round) {
      answerRequests(s);
      if (auto c = s.takeCullRequest(double(round))) s.onCulled(c->cell, {});
      const auto evicted = s.takeEvictions();
      for (uint32_t f : evicted) EXPECT_FALSE(s.held(f));
      if (s.takeBatch().empty() && evicted.empty()) break;
      EXPECT_LE(s.heldBytes(), budget);
    }
  };
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  drain();
  const uint64_t before = s.heldBytes();
  EXPECT_GT(before, 0u);
  // Walk to the street's other end: what the new cells need displaces the old.
  const glm::dvec3 far{0.0, 1.7, -24.0};
  s.setPose(far, glm::vec3(0.0f), 0.0f, 0.0f);
  std::vector<uint32_t> evicted;
  for (int round = 0; round < 100; ++round) {
    answerRequests(s);
    if (auto c = s.takeCullRequest(double(round))) s.onCulled(c->cell, {});
    auto e = s.takeEvictions();
    if (!e.empty()) {
      // Farthest first: every face still held outside the needed cells is
      // no farther than the nearest face evicted.
      std::set<uint32_t> neededNow;
      for (uint32_t l : s.neededCells())
        for (uint32_t f : *faceSet(l)) neededNow.insert(f);
      float nearestEvicted = std::numeric_limits<float>::max();
      for (uint32_t f : e)
        nearestEvicted =
            std::min(nearestEvicted, glm::length(world().faceCentre(f) - glm::vec3(far)));
      for (uint32_t f = 0; f < world().faceCount(); ++f) {
        if (s.held(f) && !neededNow.count(f)) {
          EXPECT_LE(glm::length(world().faceCentre(f) - glm::vec3(far)), nearestEvicted + 1e-3f)
              << "face " << f;
        }
      }
    }
    evicted.insert(evicted.end(), e.begin(), e.end());
    EXPECT_LE(s.heldBytes(), budget);
    if (s.takeBatch().empty() && e.empty()) break;
  }
  ASSERT_FALSE(evicted.empty());
  // No evicted face belongs to a needed cell's face set.
  std::set<uint32_t> needed;
  for (uint32_t l : s.neededCells())
    for (uint32_t f : *faceSet(l)) needed.insert(f);
  for (uint32_t f : evicted) EXPECT_FALSE(needed.count(f)) << "evicted face " << f << " is needed";
}

TEST_F(SchedulerTest, PrefetchesCellsAheadAlongTheVelocityWithABoundedNumberOfSamples) {
  StreamSchedulerConfig cfg;
  cfg.prefetchSeconds =
      1e9;  // a horizon far beyond the scene: still at most kMaxPrefetchSteps samples
  StreamScheduler s(world(), cfg, 200.0f, 0);
  s.setPose({-20.0, 1.7, 8.0}, glm::vec3(5.0f, 0.0f, 0.0f), -90.0f, 0.0f);
  const auto& needed = s.neededCells();
  EXPECT_LE(needed.size(), size_t(StreamScheduler::kMaxPrefetchSteps + 9));
  // Some cell east of the start (+x) is needed; none of the ahead samples is west of it.
  const glm::ivec3 here = *world().cellOf(glm::vec3(-20.0f, 1.7f, 8.0f));
  bool ahead = false;
  for (uint32_t l : needed) {
    const glm::ivec3 c = world().grid().cellAt(l);
    ahead = ahead || c.x > here.x + 1;
    EXPECT_GE(c.x, here.x - 1);
  }
  EXPECT_TRUE(ahead);
}

TEST_F(SchedulerTest, FacesSeenFromACellTheClientLeftNoLongerGoFirst) {
  StreamSchedulerConfig cfg;
  cfg.batchBytes = 1;  // one face a batch: the order shows
  StreamScheduler s(world(), cfg, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  answerRequests(s);
  const auto cull = s.takeCullRequest(0.0);
  ASSERT_TRUE(cull);
  s.onCulled(cull->cell, {cull->faceSet->back()});
  // The client walks to the other side of the wall before anything is sent.
  const glm::dvec3 far{0.0, 1.7, -24.0};
  s.setPose(far, glm::vec3(0.0f), 0.0f, 0.0f);
  answerRequests(s);
  const auto batch = s.takeBatch();
  ASSERT_EQ(batch.size(), 1u);
  EXPECT_EQ(batch.front(), faceSet(cellOf(far))->front())
      << "the new cell's faces come in order, not the old cell's view";
}

TEST_F(SchedulerTest, TheRadiusPolicyStreamsWithoutCulling) {
  StreamSchedulerConfig cfg;
  cfg.policy = StreamPolicy::Radius;
  StreamScheduler s(world(), cfg, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  answerRequests(s, StreamPolicy::Radius);
  EXPECT_FALSE(s.takeCullRequest(0.0));
  EXPECT_TRUE(s.readyToStream(false));
  EXPECT_FALSE(s.takeBatch().empty());
}

TEST_F(SchedulerTest, PrefetchBacksOffWhileTheWorkersAreBehindAndADroppedOneWaitsToBeAskedAgain) {
  StreamScheduler s(world(), {}, 200.0f, 0);
  s.setBehind(true);
  s.setPose(kPoint, glm::vec3(1.4f, 0.0f, 0.0f), -90.0f, 0.0f);
  ASSERT_GT(s.neededCells().size(), 1u) << "cells to prefetch";
  const auto behind = s.takeCellRequests(0.0);
  ASSERT_EQ(behind.size(), 1u) << "only the current cell while behind";
  EXPECT_EQ(behind[0].cell, cellOf(kPoint));
  EXPECT_EQ(behind[0].priority.rank, WorkPriority::Current);
  s.onFaceSet(behind[0].cell, faceSet(behind[0].cell));
  EXPECT_TRUE(s.takeCellRequests(0.0).empty());
  s.setBehind(false);
  const auto prefetch = s.takeCellRequests(10.0);
  ASSERT_FALSE(prefetch.empty());
  for (const auto& r : prefetch) {
    EXPECT_EQ(r.priority.rank, WorkPriority::Prefetch);
    EXPECT_GE(r.priority.dueS, 10.0) << "due when the client gets there, not before now";
  }
  // The queue drops the first: it is not asked again within kRetryAfterDropS.
  const uint32_t droppedCell = prefetch[0].cell;
  s.onDropped(droppedCell, prefetch[0].level, 10.0);
  EXPECT_FALSE(s.isRequested(droppedCell));
  for (const auto& r : s.takeCellRequests(10.0 + StreamScheduler::kRetryAfterDropS / 2))
    EXPECT_NE(r.cell, droppedCell);
  bool askedAgain = false;
  for (const auto& r : s.takeCellRequests(10.0 + StreamScheduler::kRetryAfterDropS))
    askedAgain = askedAgain || r.cell == droppedCell;
  EXPECT_TRUE(askedAgain);
}

// The street world of the coarse-first tests and their oracle: a cell's PVS
// within the radius computed directly (EpsilonPvs on the cell's box, no
// candidate faces).
struct DirectPvs {
  static constexpr float kRadius = 15.0f;  // small: the coarse set's wider reach shows too
  StreamWorld world{streetScene(), StreamWorldOptions{}};
  EpsilonPvs direct{world.scene()};
  boost::asio::thread_pool pool{2};

  FaceListPtr faceSet(uint32_t cell, CellLevel level) {
    std::promise<FaceListPtr> p;
    world.cellFaceSet(
        world.grid().cellAt(cell), level, StreamPolicy::Visibility, kRadius, pool,
        [&](FaceListPtr f) { p.set_value(f); }, CellWork{});
    return p.get_future().get();
  }
  FaceList oracle(const Box3f& box) const {
    FaceList out;
    const FaceList pvs = direct.compute(box).faces, near = world.facesWithin(box, kRadius);
    std::set_intersection(pvs.begin(), pvs.end(), near.begin(), near.end(),
                          std::back_inserter(out));
    return out;
  }
};

// Coarse first, then the cell's own set: at every step the client holds
// every face of the cell's PVS within the radius as computed directly (the
// oracle: EpsilonPvs on the cell's box, no candidate faces), and the cell is
// announced ready only then.
TEST(SchedulerCoarseFirst, NeverLeavesTheClientWithoutAFaceOfTheCellsOwnPvs) {
  DirectPvs d;
  StreamWorld& world = d.world;
  ASSERT_TRUE(world.coarseFirst());
  constexpr float kRadius = DirectPvs::kRadius;
  auto faceSet = [&](uint32_t cell, CellLevel level) { return d.faceSet(cell, level); };
  StreamSchedulerConfig cfg;
  cfg.coarseFirst = true;
  const ViewCellGrid& grid = world.grid();
  size_t cellsTried = 0, coarseLarger = 0;
  for (int z = 0; z < grid.dims().z; z += 3)
    for (int x = 0; x < grid.dims().x; x += 3) {
      const glm::ivec3 cell(x, 0, z);
      const Box3f box = grid.cellBox(cell);
      SCOPED_TRACE(::testing::Message() << "cell " << x << ", " << z);
      const FaceList oracle = d.oracle(box);
      StreamScheduler s(world, cfg, kRadius, 0);
      s.setPose(glm::dvec3(box.center()), glm::vec3(0.0f), 0.0f, 0.0f);
      const uint32_t here = uint32_t(grid.linearIndex(cell));
      std::vector<StreamScheduler::CellRequest> refinements;
      auto drain = [&] {
        for (int round = 0; round < 1000; ++round) {
          for (auto& r : s.takeCellRequests(0.0)) {
            if (r.priority.rank == WorkPriority::Refine)
              refinements.push_back(std::move(r));
            else
              s.onFaceSet(r.cell, faceSet(r.cell, r.level), r.level);
          }
          if (auto c = s.takeCullRequest(double(round))) s.onCulled(c->cell, {});
          if (s.takeBatch().empty()) break;
        }
      };
      drain();
      EXPECT_FALSE(s.hasFineSet(here)) << "coarse first";
      auto missing = [&] {
        size_t n = 0;
        for (uint32_t f : oracle) n += !s.held(f);
        return n;
      };
      EXPECT_EQ(missing(), 0u) << "faces of the cell's own PVS missing after the coarse set";
      bool ready = false;
      for (const auto& r : s.takeReadyCells()) ready = ready || r.cell == cell;
      EXPECT_TRUE(ready);
      // The refinement: the cell's own set, after the coarse one.
      ASSERT_EQ(refinements.size(), 1u);
      EXPECT_EQ(refinements[0].cell, here);
      EXPECT_EQ(refinements[0].level, CellLevel::Fine);
      const FaceListPtr coarse = faceSet(here, CellLevel::Coarse);
      const FaceListPtr fine = faceSet(here, CellLevel::Fine);
      EXPECT_TRUE(std::includes(coarse->begin(), coarse->end(), fine->begin(), fine->end()))
          << "the coarse set contains the cell's own";
      coarseLarger += coarse->size() > fine->size();
      EXPECT_TRUE(s.onFaceSet(here, fine, CellLevel::Fine));
      EXPECT_TRUE(s.hasFineSet(here));
      drain();
      EXPECT_EQ(missing(), 0u) << "faces of the cell's own PVS missing after the refinement";
      EXPECT_FALSE(s.onFaceSet(here, coarse, CellLevel::Coarse)) << "a late coarse set is moot";
      ++cellsTried;
    }
  EXPECT_GT(cellsTried, 4u);
  EXPECT_GT(coarseLarger, 0u) << "somewhere the coarse set is larger, so refining matters";
}

// Unculled first, for a server whose workers are behind: every needed cell
// (prefetch included) is asked for its unculled set at once, at rank
// Immediate; the current cell refines to the coarse set and then to its own
// once the workers catch up; at every step the client holds every face of
// the cell's PVS within the radius computed directly (the oracle: EpsilonPvs
// on the cell's box), and under a memory budget the refinement lets go of
// faces outside the cell's own set only.
TEST(SchedulerUnculledFirst,
     ServesTheCurrentCellAtOnceWhileLaggingThenRefinesEvictingOnlyFacesOutsideIt) {
  DirectPvs d;
  StreamWorld& world = d.world;
  constexpr float kRadius = DirectPvs::kRadius;
  auto faceSet = [&](uint32_t cell, CellLevel level) { return d.faceSet(cell, level); };
  StreamSchedulerConfig cfg;
  cfg.coarseFirst = true;
  cfg.maxCellRequests = 4;
  const ViewCellGrid& grid = world.grid();
  size_t cellsTried = 0, evictedSome = 0;
  for (int z = 1; z < grid.dims().z; z += 4)
    for (int x = 1; x < grid.dims().x; x += 4) {
      const glm::ivec3 cell(x, 0, z);
      const Box3f box = grid.cellBox(cell);
      SCOPED_TRACE(::testing::Message() << "cell " << x << ", " << z);
      const FaceList oracle = d.oracle(box);
      const uint32_t here = uint32_t(grid.linearIndex(cell));
      const FaceListPtr unculled = faceSet(here, CellLevel::Unculled);
      // The budget holds the unculled set exactly: refining makes room.
      uint64_t budget = 0;
      for (uint32_t f : *unculled) budget += world.faceBytes(f);
      StreamScheduler s(world, cfg, kRadius, budget);
      s.setBehind(true);
      s.setLagging(true);
      s.setPose(glm::dvec3(box.center()), glm::vec3(1.4f, 0.0f, 0.0f), -90.0f, 0.0f);
      const auto requests = s.takeCellRequests(0.0);
      // Prefetch backs off: an unculled set costs the radius policy's bytes.
      ASSERT_EQ(requests.size(), 1u);
      EXPECT_EQ(requests[0].cell, here);
      for (const auto& r : requests) {
        EXPECT_EQ(r.level, CellLevel::Unculled);
        EXPECT_EQ(r.priority.rank, WorkPriority::Immediate);
      }
      EXPECT_TRUE(s.onFaceSet(here, unculled, CellLevel::Unculled));
      std::vector<uint32_t> evicted;
      auto drain = [&] {
        for (int round = 0; round < 10000; ++round) {
          if (auto c = s.takeCullRequest(double(round))) s.onCulled(c->cell, {});
          for (uint32_t f : s.takeEvictions()) evicted.push_back(f);
          if (s.takeBatch().empty()) break;
        }
      };
      auto missing = [&] {
        size_t n = 0;
        for (uint32_t f : oracle) n += !s.held(f);
        return n;
      };
      drain();
      EXPECT_EQ(missing(), 0u) << "after the unculled set";
      EXPECT_EQ(s.heldBytes(), budget);
      bool ready = false;
      for (const auto& r : s.takeReadyCells()) ready = ready || r.cell == cell;
      EXPECT_TRUE(ready);
      for (const auto& r : s.takeCellRequests(0.0))
        EXPECT_NE(r.cell, here) << "no refinement while behind";
      // Caught up: the coarse set, then the cell's own.
      s.setBehind(false);
      s.setLagging(false);
      for (CellLevel level : {CellLevel::Coarse, CellLevel::Fine}) {
        std::optional<StreamScheduler::CellRequest> refinement;
        for (auto& r : s.takeCellRequests(1.0))
          if (r.cell == here) refinement = std::move(r);
        ASSERT_TRUE(refinement);
        EXPECT_EQ(refinement->level, level);
        EXPECT_EQ(refinement->priority.rank, WorkPriority::Refine);
        EXPECT_TRUE(s.onFaceSet(here, faceSet(here, level), level));
        EXPECT_EQ(s.loadedLevel(here), level);
        drain();
        EXPECT_EQ(missing(), 0u) << "after the refinement";
      }
      const FaceListPtr own = faceSet(here, CellLevel::Fine);
      for (uint32_t f : evicted)
        EXPECT_FALSE(std::binary_search(own->begin(), own->end(), f))
            << "face " << f << " of the cell's own set evicted";
      evictedSome += !evicted.empty();
      ++cellsTried;
    }
  EXPECT_GT(cellsTried, 4u);
  EXPECT_GT(evictedSome, 0u) << "somewhere the refinement made room";
}

// Not behind: the current cell waits for its coarse set, and gets the
// unculled one too once it has waited unculledAfterS; whichever is tighter
// wins, and a looser set arriving later is moot. (A world of its own: no
// face set is cached before.)
TEST(SchedulerUnculledFirst, BehindButNotLaggingTheCurrentCellWaitsForItsCoarseSet) {
  DirectPvs d;
  StreamSchedulerConfig cfg;
  cfg.coarseFirst = true;
  const glm::ivec3 cell(1, 0, 1);
  const Box3f box = d.world.grid().cellBox(cell);
  StreamScheduler s(d.world, cfg, DirectPvs::kRadius, 0);
  s.setBehind(true);  // many jobs queued, none waiting long yet
  s.setPose(glm::dvec3(box.center()), glm::vec3(1.4f, 0.0f, 0.0f), -90.0f, 0.0f);
  const auto requests = s.takeCellRequests(0.0);
  ASSERT_EQ(requests.size(), 1u) << "prefetch backs off";
  EXPECT_EQ(requests[0].cell, uint32_t(d.world.grid().linearIndex(cell)));
  EXPECT_EQ(requests[0].level, CellLevel::Coarse);
  EXPECT_EQ(requests[0].priority.rank, WorkPriority::Current);
}

TEST(SchedulerUnculledFirst, ACurrentCellWaitingTooLongGetsItsUnculledSetAndATighterSetStillWins) {
  StreamWorld world(streetScene(), StreamWorldOptions{});
  boost::asio::thread_pool pool(2);
  StreamSchedulerConfig cfg;
  cfg.coarseFirst = true;
  cfg.unculledAfterS = 1.0;
  StreamScheduler s(world, cfg, 200.0f, 0);
  s.setPose(kPoint, glm::vec3(0.0f), 0.0f, 0.0f);
  const uint32_t here = uint32_t(world.grid().linearIndex(*world.cellOf(glm::vec3(kPoint))));
  const auto first = s.takeCellRequests(10.0);
  ASSERT_FALSE(first.empty());
  EXPECT_EQ(first[0].cell, here);
  EXPECT_EQ(first[0].level, CellLevel::Coarse);
  EXPECT_EQ(first[0].priority.rank, WorkPriority::Current);
  for (const auto& r : s.takeCellRequests(10.5)) EXPECT_NE(r.level, CellLevel::Unculled);
  const auto late = s.takeCellRequests(11.0);
  ASSERT_EQ(late.size(), 1u);
  EXPECT_EQ(late[0].cell, here);
  EXPECT_EQ(late[0].level, CellLevel::Unculled);
  EXPECT_EQ(late[0].priority.rank, WorkPriority::Immediate);
  auto set = [&](CellLevel level) {
    std::promise<FaceListPtr> p;
    world.cellFaceSet(
        world.grid().cellAt(here), level, StreamPolicy::Visibility, 200.0f, pool,
        [&](FaceListPtr f) { p.set_value(f); }, CellWork{});
    return p.get_future().get();
  };
  EXPECT_TRUE(s.onFaceSet(here, set(CellLevel::Coarse), CellLevel::Coarse));
  EXPECT_FALSE(s.onFaceSet(here, set(CellLevel::Unculled), CellLevel::Unculled))
      << "looser than the coarse set already loaded";
  EXPECT_EQ(s.loadedLevel(here), CellLevel::Coarse);
}

}  // namespace
}  // namespace vistream::testing
