// Stateless and small-state random numbers that give the same values on
// every machine and thread count (the standard distributions do not: their
// algorithms are implementation-defined).
//
// mixBits is SplitMix64's finaliser (Steele, Lea and Flood 2014): a hash from
// integers to well-mixed bits, for seeds derived from indices and positions.
// SplitMix is the generator built on it: one 64-bit state, advanced by the
// golden-ratio increment, ample for Monte Carlo sampling (each caller seeds
// one per point, vertex or texel, so work can be split any way).
#pragma once

#include <cmath>
#include <cstdint>

namespace vistream {

inline uint64_t mixBits(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// Uniform in [0, 1) from the top 53 bits of x.
inline double unitInterval(uint64_t x) {
  return double(x >> 11) * 0x1.0p-53;
}

class SplitMix {
 public:
  explicit SplitMix(uint64_t seed) : state_(seed) {}

  uint64_t next() {
    state_ += 0x9e3779b97f4a7c15ull;
    return mixBits(state_);
  }
  // Uniform in [0, 1).
  double uniform() { return unitInterval(next()); }
  // Standard normal (Box-Muller; one of the pair).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }

 private:
  uint64_t state_;
};

}  // namespace vistream
