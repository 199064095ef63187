// A latency histogram with fixed bucket bounds, as a Prometheus histogram
// is exposed: observe() from any thread without a lock, snapshot() for the
// metrics page.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>

namespace vistream {

class LatencyHistogram {
 public:
  // Upper bounds in seconds (the last bucket, +Inf, is implied).
  static constexpr std::array<double, 11> kBounds{0.001, 0.0025, 0.005, 0.01, 0.025, 0.05,
                                                  0.1,   0.25,   0.5,   1.0,  5.0};

  void observe(double seconds) {
    size_t b = 0;
    while (b < kBounds.size() && seconds > kBounds[b]) ++b;
    buckets_[b].fetch_add(1, std::memory_order_relaxed);
    sumMicros_.fetch_add(uint64_t(seconds * 1e6 + 0.5), std::memory_order_relaxed);
  }
  void observeSince(std::chrono::steady_clock::time_point start) {
    observe(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }

  struct Snapshot {
    std::array<uint64_t, kBounds.size()> cumulative{};  // observations <= kBounds[i]
    uint64_t count = 0;
    double sumSeconds = 0.0;
  };
  Snapshot snapshot() const {
    Snapshot s;
    uint64_t running = 0;
    for (size_t b = 0; b < kBounds.size(); ++b) {
      running += buckets_[b].load(std::memory_order_relaxed);
      s.cumulative[b] = running;
    }
    s.count = running + buckets_[kBounds.size()].load(std::memory_order_relaxed);
    s.sumSeconds = double(sumMicros_.load(std::memory_order_relaxed)) / 1e6;
    return s;
  }

 private:
  std::array<std::atomic<uint64_t>, kBounds.size() + 1> buckets_{};
  std::atomic<uint64_t> sumMicros_{0};
};

}  // namespace vistream
