// The order and bound of visibility work: one worker held busy while jobs
// queue up, then released; the order they ran in and what was dropped are
// checked against the ordering rule applied by hand (a sort of what was
// submitted).
#include "server/stream/work_queue.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <boost/asio/thread_pool.hpp>
#include <condition_variable>
#include <mutex>
#include <random>
#include <thread>

#include "server/stream/async_cache.h"

namespace vistream::testing {
namespace {

// A one-thread pool whose thread is held by a job until release().
class HeldWorker {
 public:
  explicit HeldWorker(WorkQueue& queue) {
    queue.submit(pool_.get_executor(), {WorkPriority::Current, -1e9}, [this] {
      std::unique_lock lock(mutex_);
      started_ = true;
      changed_.notify_all();
      changed_.wait(lock, [this] { return released_; });
    });
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [this] { return started_; });  // the worker is inside the job
  }
  ~HeldWorker() {
    release();
    pool_.join();
  }
  void release() {
    std::lock_guard lock(mutex_);
    released_ = true;
    changed_.notify_all();
  }
  void finish() {
    release();
    pool_.join();
  }
  boost::asio::thread_pool& pool() { return pool_; }

 private:
  boost::asio::thread_pool pool_{1};
  std::mutex mutex_;
  std::condition_variable changed_;
  bool started_ = false, released_ = false;
};

// What ran, in order (jobs run on the one worker, one at a time).
struct RunLog {
  std::mutex mutex;
  std::vector<int> ran, dropped;
  std::function<void()> job(int id) {
    return [this, id] {
      std::lock_guard lock(mutex);
      ran.push_back(id);
    };
  }
  std::function<void()> drop(int id) {
    return [this, id] {
      std::lock_guard lock(mutex);
      dropped.push_back(id);
    };
  }
};

TEST(WorkQueue, ACurrentCellOvertakesQueuedPrefetchAndPrefetchRunsNearestInTimeFirst) {
  WorkQueue queue(100);
  RunLog log;
  {
    HeldWorker worker(queue);
    auto ex = worker.pool().get_executor();
    // Prefetch due at 5, 1, 3 s; refinement due at once; then two clients'
    // current cells, the later one submitted first but due later.
    queue.submit(ex, {WorkPriority::Prefetch, 5.0}, log.job(5));
    queue.submit(ex, {WorkPriority::Prefetch, 1.0}, log.job(1));
    queue.submit(ex, {WorkPriority::Refine, 0.0}, log.job(100));
    queue.submit(ex, {WorkPriority::Prefetch, 3.0}, log.job(3));
    queue.submit(ex, {WorkPriority::Current, 0.2}, log.job(-2));
    queue.submit(ex, {WorkPriority::Current, 0.1}, log.job(-1));
    EXPECT_EQ(queue.load().waiting, 6u);
    EXPECT_EQ(queue.load().waitingCurrent, 2u);
    worker.finish();
  }
  EXPECT_EQ(log.ran, (std::vector<int>{-1, -2, 1, 3, 5, 100}));
  EXPECT_TRUE(log.dropped.empty());
  EXPECT_EQ(queue.load().waiting, 0u);
}

TEST(WorkQueue, UnderAFloodKeepsOnlyTheMostUrgentPrefetchAndEveryCurrentCell) {
  constexpr size_t kBound = 8;
  WorkQueue queue(kBound);
  RunLog log;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> due(0.0, 100.0);
  std::vector<std::pair<double, int>> prefetch;
  std::vector<int> current;
  size_t maxWaiting = 0;
  {
    HeldWorker worker(queue);
    auto ex = worker.pool().get_executor();
    for (int i = 0; i < 2000; ++i) {
      if (i % 40 == 0) {  // 50 current cells among the flood
        current.push_back(-1 - i);
        queue.submit(ex, {WorkPriority::Current, due(rng)}, log.job(current.back()),
                     log.drop(current.back()));
      } else {
        const double d = due(rng);
        prefetch.emplace_back(d, i);
        queue.submit(ex, {WorkPriority::Prefetch, d}, log.job(i), log.drop(i));
      }
      maxWaiting = std::max(maxWaiting, queue.load().waiting);
    }
    EXPECT_EQ(queue.load().dropped, prefetch.size() - kBound);
    worker.finish();
  }
  // Bounded: never more than the bound of prefetch beside the current cells.
  EXPECT_LE(maxWaiting, kBound + current.size());
  // Every current cell ran, first; then the kBound prefetch jobs due soonest
  // (the oracle: all prefetch sorted by due time), in that order.
  std::sort(prefetch.begin(), prefetch.end());
  std::vector<int> expectedPrefetch;
  for (size_t i = 0; i < kBound; ++i) expectedPrefetch.push_back(prefetch[i].second);
  ASSERT_EQ(log.ran.size(), current.size() + kBound);
  std::vector<int> ranCurrent(log.ran.begin(), log.ran.begin() + long(current.size()));
  std::sort(ranCurrent.begin(), ranCurrent.end());
  std::sort(current.begin(), current.end());
  EXPECT_EQ(ranCurrent, current);
  EXPECT_EQ(std::vector<int>(log.ran.begin() + long(current.size()), log.ran.end()),
            expectedPrefetch);
  // Everything else was dropped, each told once.
  std::vector<int> dropped = log.dropped, expectedDropped;
  for (size_t i = kBound; i < prefetch.size(); ++i) expectedDropped.push_back(prefetch[i].second);
  std::sort(dropped.begin(), dropped.end());
  std::sort(expectedDropped.begin(), expectedDropped.end());
  EXPECT_EQ(dropped, expectedDropped);
}

TEST(WorkQueue, ReportsTheWaitOfTheOldestCurrentCellAndFallsBehindOnIt) {
  WorkQueue queue(10);
  HeldWorker worker(queue);
  auto ex = worker.pool().get_executor();
  EXPECT_FALSE(queue.behind(0.0, 10));
  queue.submit(ex, {WorkPriority::Prefetch, 0.0}, [] {});
  EXPECT_EQ(queue.load().oldestCurrentS, 0.0) << "prefetch is not a current cell";
  EXPECT_FALSE(queue.behind(0.0, 0)) << "waiting prefetch alone is not falling behind";
  queue.submit(ex, {WorkPriority::Current, 0.0}, [] {});
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  queue.submit(ex, {WorkPriority::Current, 0.0}, [] {});
  const WorkQueue::Load l = queue.load();
  EXPECT_EQ(l.waiting, 3u);
  EXPECT_EQ(l.waitingCurrent, 2u);
  EXPECT_GE(l.oldestCurrentS, 0.05) << "the first current cell has waited at least 50 ms";
  EXPECT_TRUE(queue.behind(0.04, 10));
  EXPECT_FALSE(queue.behind(1e9, 10));
  EXPECT_TRUE(queue.behind(1e9, 1)) << "more current cells waiting than allowed";
  worker.finish();
  EXPECT_FALSE(queue.behind(0.0, 0));
}

// Immediate jobs (a face set needing no visibility computation, encoding a
// batch) go before every current cell, are not counted as falling behind,
// and are never dropped for the bound however many wait.
TEST(WorkQueue, ImmediateJobsOvertakeCurrentCellsAreNeverDroppedAndAreNotFallingBehind) {
  constexpr size_t kBound = 2;
  WorkQueue queue(kBound);
  RunLog log;
  {
    HeldWorker worker(queue);
    auto ex = worker.pool().get_executor();
    queue.submit(ex, {WorkPriority::Prefetch, 0.0}, log.job(10), log.drop(10));
    queue.submit(ex, {WorkPriority::Current, 0.0}, log.job(1), log.drop(1));
    for (int i = 0; i < 5; ++i)
      queue.submit(ex, {WorkPriority::Immediate, double(5 - i)}, log.job(100 + i),
                   log.drop(100 + i));
    queue.submit(ex, {WorkPriority::Refine, 0.0}, log.job(20), log.drop(20));
    queue.submit(ex, {WorkPriority::Prefetch, 1.0}, log.job(11), log.drop(11));
    EXPECT_TRUE(log.dropped == std::vector<int>{20}) << "only the refinement, over the bound";
    const WorkQueue::Load l = queue.load();
    EXPECT_EQ(l.waiting, 8u);
    EXPECT_EQ(l.waitingCurrent, 1u) << "immediate jobs are not current cells";
    EXPECT_EQ(l.waitingDroppable, 2u) << "nor prefetch";
    EXPECT_FALSE(queue.behind(1e9, 1));
    worker.finish();
  }
  // Immediate by due time, then the current cell, then prefetch by due time.
  EXPECT_EQ(log.ran, (std::vector<int>{104, 103, 102, 101, 100, 1, 10, 11}));
}

TEST(WorkQueue, AbandonedItDropsEverythingWaitingWhateverItsRankAndRefusesMore) {
  WorkQueue queue(10);
  RunLog log;
  HeldWorker worker(queue);
  auto ex = worker.pool().get_executor();
  queue.submit(ex, {WorkPriority::Current, 0.0}, log.job(1), log.drop(1));
  queue.submit(ex, {WorkPriority::Prefetch, 0.0}, log.job(2), log.drop(2));
  queue.abandon();
  EXPECT_EQ(queue.submit(ex, {WorkPriority::Current, 0.0}, log.job(3), log.drop(3)), 0u);
  worker.finish();
  EXPECT_TRUE(log.ran.empty());
  std::sort(log.dropped.begin(), log.dropped.end());
  EXPECT_EQ(log.dropped, (std::vector<int>{1, 2}));
  EXPECT_EQ(queue.load().waiting, 0u);
}

TEST(WorkQueue, ACacheRequestForACurrentCellRaisesTheQueuedPrefetchItJoins) {
  WorkQueue queue(10);
  std::mutex mutex;
  std::vector<int> order;
  AsyncCache<int, int> cache(
      16,
      [&](const int& k) {
        std::lock_guard lock(mutex);
        order.push_back(k);
        return k;
      },
      {}, std::numeric_limits<size_t>::max(), {}, &queue);
  HeldWorker worker(queue);
  auto ex = worker.pool().get_executor();
  std::atomic<int> answered{0};
  auto done = [&](AsyncCache<int, int>::Ptr) { ++answered; };
  cache.get(1, ex, done, nullptr, {WorkPriority::Prefetch, 1.0});
  cache.get(2, ex, done, nullptr, {WorkPriority::Prefetch, 2.0});
  cache.get(3, ex, done, nullptr, {WorkPriority::Current, 5.0});
  // A client now stands in cell 2: its request joins the queued prefetch.
  cache.get(2, ex, done, nullptr, {WorkPriority::Current, 3.0});
  worker.finish();
  EXPECT_EQ(order, (std::vector<int>{2, 3, 1}));
  EXPECT_EQ(answered.load(), 4);
}

TEST(WorkQueue, ACacheComputationDroppedForTheBoundTellsItsWaitersAndIsAskedAgain) {
  WorkQueue queue(1);
  AsyncCache<int, int> cache(
      16, [](const int& k) { return k; }, {}, std::numeric_limits<size_t>::max(), {}, &queue);
  HeldWorker worker(queue);
  auto ex = worker.pool().get_executor();
  std::atomic<int> answered{0}, dropped{0};
  auto done = [&](AsyncCache<int, int>::Ptr) { ++answered; };
  auto drop = [&] { ++dropped; };
  cache.get(1, ex, done, nullptr, {WorkPriority::Prefetch, 1.0}, drop);
  cache.get(2, ex, done, nullptr, {WorkPriority::Prefetch, 2.0}, drop);  // the least urgent
  EXPECT_EQ(dropped.load(), 1);
  EXPECT_EQ(cache.dropped(), 1u);
  cache.get(2, ex, done, nullptr, {WorkPriority::Current, 0.0}, drop);  // asked again, now
  worker.finish();
  EXPECT_EQ(answered.load(), 2);
  EXPECT_TRUE(cache.contains(1));
  EXPECT_TRUE(cache.contains(2));
}

}  // namespace
}  // namespace vistream::testing
