// The cache the server's visibility work goes through: computed once,
// cancelled when nobody waits any more, bounded by entries and by cost.
#include "server/stream/async_cache.h"

#include <gtest/gtest.h>

#include <boost/asio/io_context.hpp>
#include <string>

namespace vistream {
namespace {

// An executor whose posted work runs only when the test says so.
struct ManualPool {
  boost::asio::io_context io;
  void runAll() {
    io.restart();
    io.run();
  }
};

TEST(AsyncCache, AComputationWhoseWaitersAllLetGoIsNeverRun) {
  ManualPool pool;
  int computed = 0;
  AsyncCache<int, std::string> cache(8, [&](const int& k) {
    ++computed;
    return std::to_string(k);
  });
  int called = 0;
  {
    Interest interest = makeInterest();
    cache.get(
        1, pool.io.get_executor(), [&](auto) { ++called; }, interest);
  }  // dropped before the pool ran
  pool.runAll();
  EXPECT_EQ(computed, 0);
  EXPECT_EQ(called, 0);
  EXPECT_EQ(cache.cancelled(), 1u);
  // Asked again, it is computed.
  Interest again = makeInterest();
  cache.get(
      1, pool.io.get_executor(), [&](auto v) { called += *v == "1"; }, again);
  pool.runAll();
  EXPECT_EQ(computed, 1);
  EXPECT_EQ(called, 1);
}

TEST(AsyncCache, OneWaiterStillInterestedKeepsTheComputationAndEveryWaiterHearsOfIt) {
  ManualPool pool;
  int computed = 0;
  AsyncCache<int, int> cache(8, [&](const int& k) {
    ++computed;
    return k * 2;
  });
  int calls = 0;
  Interest kept = makeInterest();
  {
    Interest dropped = makeInterest();
    cache.get(
        3, pool.io.get_executor(), [&](auto v) { calls += *v == 6; }, dropped);
  }
  cache.get(
      3, pool.io.get_executor(), [&](auto v) { calls += *v == 6; }, kept);
  pool.runAll();
  EXPECT_EQ(computed, 1);
  EXPECT_EQ(calls, 2);
  // A request without an interest is never cancelled.
  cache.get(4, pool.io.get_executor(), [&](auto v) { calls += *v == 8; });
  pool.runAll();
  EXPECT_EQ(calls, 3);
}

TEST(AsyncCache, KeepsTheMostRecentlyUsedValuesWithinTheirTotalCost) {
  ManualPool pool;
  AsyncCache<int, std::string> cache(
      100, [](const int& k) { return std::string(size_t(k), 'x'); }, {}, 100,
      [](const std::string& v) { return v.size(); });
  for (int k : {40, 30, 20}) cache.get(k, pool.io.get_executor(), [](auto) {});
  pool.runAll();
  EXPECT_EQ(cache.cost(), 90u);
  ASSERT_TRUE(cache.find(40));  // 40 is now the most recently used
  cache.get(25, pool.io.get_executor(), [](auto) {});
  pool.runAll();
  // 115 > 100: the least recently used (30) goes; 40, 20 and 25 stay.
  EXPECT_EQ(cache.cost(), 85u);
  EXPECT_FALSE(cache.find(30));
  EXPECT_TRUE(cache.find(40));
  EXPECT_TRUE(cache.find(20));
  EXPECT_TRUE(cache.find(25));
  // A value costing more than the limit alone is still kept (until the next).
  cache.get(150, pool.io.get_executor(), [](auto) {});
  pool.runAll();
  EXPECT_TRUE(cache.find(150));
  EXPECT_EQ(cache.size(), 1u);
}

TEST(AsyncCache, AComputationThatThrowsCachesNothingAndTellsItsWaitersWithNull) {
  ManualPool pool;
  int attempts = 0;
  std::string error;
  AsyncCache<int, int> cache(
      8,
      [&](const int&) -> int {
        ++attempts;
        throw std::runtime_error("boom");
      },
      [&](const int&, const char* what) { error = what; });
  bool gotNull = false;
  cache.get(1, pool.io.get_executor(), [&](auto v) { gotNull = v == nullptr; });
  pool.runAll();
  EXPECT_TRUE(gotNull);
  EXPECT_EQ(error, "boom");
  cache.get(1, pool.io.get_executor(), [](auto) {});
  pool.runAll();
  EXPECT_EQ(attempts, 2);
}

}  // namespace
}  // namespace vistream
