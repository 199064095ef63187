// Coalescing of prefetch batches (StreamScheduler, stream_scheduler.h):
// checked against the world's own face sets over a walk along the street.
#include <gtest/gtest.h>

#include <future>
#include <set>

#include "server/stream/stream_scheduler.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

class CoalescingTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { world_ = new StreamWorld(streetScene(), StreamWorldOptions{}); }
  static void TearDownTestSuite() {
    delete world_;
    world_ = nullptr;
  }
  FaceListPtr faceSet(uint32_t cell) {
    std::promise<FaceListPtr> p;
    world_->cellFaceSet(world_->grid().cellAt(cell), StreamPolicy::Visibility, 200.0f, pool_,
                        [&](FaceListPtr f) { p.set_value(f); });
    return p.get_future().get();
  }
  uint32_t cellOf(const glm::dvec3& p) {
    return uint32_t(world_->grid().linearIndex(*world_->cellOf(glm::vec3(p))));
  }

  // What a walk sent: its batches, and how many cells it announced ready.
  struct Walk {
    std::vector<std::vector<uint32_t>> batches;
    size_t announced = 0;
  };
  // Along the street at walking speed, 10 poses a second: every face set
  // asked for answered with the world's own, the culling with nothing in
  // view, then every batch the scheduler gives. Checks, at every step, that
  // each cell announced ready had every face of its face set sent before,
  // and that no face of the cell the client stands in is held back.
  Walk walk(size_t coalesceBytes) {
    StreamSchedulerConfig cfg;
    cfg.coalesceBytes = coalesceBytes;
    StreamScheduler s(*world_, cfg, 200.0f, 0);
    std::set<uint32_t> sent;
    Walk w;
    const glm::vec3 velocity(1.4f, 0.0f, 0.0f);
    for (int step = 0; step <= 200; ++step) {
      const double t = 0.1 * step;
      const glm::dvec3 eye(-14.0 + 1.4 * t, 1.7, 8.0);
      s.setPose(eye, velocity, -90.0f, 0.0f);
      for (auto& r : s.takeCellRequests(t)) s.onFaceSet(r.cell, faceSet(r.cell));
      if (auto cull = s.takeCullRequest(t)) s.onCulled(cull->cell, {});
      if (!s.readyToStream(false)) continue;
      while (true) {
        auto batch = s.takeBatch();
        if (batch.empty()) break;
        sent.insert(batch.begin(), batch.end());
        w.batches.push_back(std::move(batch));
      }
      for (const auto& ready : s.takeReadyCells()) {
        ++w.announced;
        const uint32_t l = uint32_t(world_->grid().linearIndex(ready.cell));
        for (uint32_t f : *faceSet(l))
          EXPECT_TRUE(sent.count(f)) << "cell " << l << " announced before its face " << f
                                     << " was sent (step " << step << ")";
      }
      for (uint32_t f : *faceSet(cellOf(eye)))
        EXPECT_TRUE(sent.count(f))
            << "face " << f << " of the current cell held back (step " << step << ")";
    }
    return w;
  }

  static StreamWorld* world_;
  boost::asio::thread_pool pool_{2};
};
StreamWorld* CoalescingTest::world_ = nullptr;

TEST_F(CoalescingTest, NeverAnnouncesACellBeforeAllItsFacesWereSentNorHoldsBackTheCurrentCell) {
  const Walk coalesced = walk(8u << 10);
  EXPECT_GT(coalesced.announced, 1u);
}

TEST_F(CoalescingTest, SendsFewerBatchesThanSendingEachDeltaAtOnce) {
  const Walk eager = walk(0), coalesced = walk(8u << 10);
  size_t eagerFaces = 0, coalescedFaces = 0;
  for (const auto& b : eager.batches) eagerFaces += b.size();
  for (const auto& b : coalesced.batches) coalescedFaces += b.size();
  EXPECT_LT(coalesced.batches.size(), eager.batches.size());
  EXPECT_LE(coalescedFaces, eagerFaces) << "coalescing never sends more faces";
}

}  // namespace
}  // namespace vistream::testing
