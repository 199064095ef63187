// Seeded random numbers for the procedural scenes, identical on every machine.
//
// The standard distributions (std::uniform_real_distribution and friends, and
// std::shuffle) are implementation-defined, so the same seed would give other
// scenes with another standard library. Only the std::mt19937_64 engine is
// fully specified; everything on top of it is written out here.
//
// Private to common/generate. Not thread safe: one instance per generator.
#pragma once

#include <cstdint>
#include <random>
#include <utility>
#include <vector>

#include "common/core/random.h"

namespace vistream::generate_detail {

class SceneRandom {
 public:
  explicit SceneRandom(uint64_t seed) : engine_(seed) {}

  // Uniform in [0, 1) from the top 53 bits of one engine draw.
  double uniform() { return unitInterval(engine_()); }

  // Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

  // Uniform integer in [0, n), n > 0, unbiased by rejection.
  uint64_t below(uint64_t n) {
    const uint64_t limit = UINT64_MAX - UINT64_MAX % n;
    uint64_t x = engine_();
    while (x >= limit) x = engine_();
    return x % n;
  }

  // Uniform integer in [lo, hi] (inclusive).
  int integer(int lo, int hi) { return lo + int(below(uint64_t(int64_t(hi) - lo + 1))); }

  bool chance(double probability) { return uniform() < probability; }

  // Fisher-Yates shuffle with our own integer draws.
  template <typename T>
  void shuffle(std::vector<T>& items) {
    for (size_t i = items.size(); i > 1; --i) std::swap(items[i - 1], items[size_t(below(i))]);
  }

 private:
  std::mt19937_64 engine_;
};

// The stateless hash for noise lattices indexed by position (core/random.h).
using vistream::mixBits;

}  // namespace vistream::generate_detail
