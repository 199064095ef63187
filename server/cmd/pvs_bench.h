// `vistream-pvs bench`: the measurements of Cohen-Or and Zadicario 1998
// (Tables 1 and 2) on the generated cities, and what accuracy costs in time:
// for every method and combination (paper, + back faces, + fused occlusion
// horizons), PVS size over the sampled ground truth, missing faces and time
// per cell against cell size, and the time to bake a district. All measured
// side by side in one run. See README.md ("Benchmarks") for how to run it.
#pragma once

#include <string>
#include <vector>

namespace vistream {

struct PvsBenchOptions {
  std::vector<std::string> scenes{"city1", "city2", "interior", "bigcity"};
  size_t cells = 24;         // street cells per scene for Tables 1 and 2
  size_t accuracyCells = 6;  // cells per (scene, cell size) for the accuracy table
  int groundTruthRes = 128;  // rays per cube face side for the ground truth
  size_t groundTruthPoints = 24;
  int groundTruthProbes = 8;  // rays per triangle of a PVS face aimed from each viewpoint (0: none)
  uint64_t seed = 1;
  bool json = false;
  // The district bake (pvs_bake.h), per scene and method: a square of this
  // side (metres) around the centre of the scene's bounds, clipped to them;
  // 0: no bake.
  double districtSize = 64.0;
  float bakeCellSize = 0.0f;  // metres; 0: the server's default (StreamWorldOptions::cellSize)
  unsigned bakeThreads = 1;   // 1: one core, like ms per cell; 0: all cores
  std::string plotDir;        // if set, writes accuracy.dat and accuracy.png there
};

int runPvsBench(const PvsBenchOptions& options);

}  // namespace vistream
