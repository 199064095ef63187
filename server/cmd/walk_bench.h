// `vistream-pvs walk-bench`: Figures 8 to 11 of Bittner and Havran 2001 on
// generated interiors. For each scene it walks one generated path per
// relative speed (0.25 to 4) with every culling method on the same frames
// and reports node visibility tests, culling time and frame time (Figures 8
// to 10), frame time against p_skip (Figure 11), the visible-set
// overestimation of D and adaptive over A, and how adaptive probabilities
// compare with the best fixed p_skip at each speed.
#pragma once

#include <string>
#include <vector>

namespace vistream {

struct WalkBenchOptions {
  std::vector<std::string> scenes{"interior", "interior2"};
  size_t frames = 300;   // frames per path
  size_t occluders = 0;  // 0: the paper's, 32 for interior2 and 16 otherwise
  size_t repeats = 3;    // timings are medians over this many runs
  bool json = false;
  std::string plotDir;  // if set, writes walk_<scene>.dat and walk_<scene>.png there
};

int runWalkBench(const WalkBenchOptions& options);

}  // namespace vistream
