// The median of a sample: the middle value, or the mean of the two middle
// values of an even count; 0 for an empty sample. Benchmarks quote medians
// (the machine is shared and noisy).
#pragma once

#include <algorithm>
#include <vector>

namespace vistream {

inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(h), v.end());
  if (v.size() % 2) return v[h];
  const double upper = v[h];
  return 0.5 * (*std::max_element(v.begin(), v.begin() + std::ptrdiff_t(h)) + upper);
}

}  // namespace vistream
