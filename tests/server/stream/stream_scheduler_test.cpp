// The streaming policy without sockets: poses and budgets in, requests and
// batches out, checked against the world's own face sets and a brute-force
// replay of what the client holds.
#include "server/stream/stream_scheduler.h"

#include <gtest/gtest.h>

#include <future>
#include <limits>

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

}  // namespace
}  // namespace vistream::testing
