// A scene read for measuring PVSs against the sampled ground truth
// (common/raycast/sampled_visibility.h), shared by `vistream-pvs bench` and
// `vistream-pvs cell --ground-truth`: the static world, the PVS over it, the
// oracle's rays over the sealed surface, and a comparison of one cell's PVS
// with what is sampled as seen from it.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "common/scene/scene.h"
#include "common/world/static_world.h"
#include "server/visibility/epsilon_pvs.h"

namespace vistream {

struct PvsWorld {
  Scene scene;
  StaticWorld statics;  // triangles, rays, solids, free space (static_world.h)
  std::unique_ptr<EpsilonPvs> pvs;
  // The oracle's rays: the surface with sub-tolerance cracks closed, as the
  // solids behind back-face culling and fusion read it (sealed_surface.h).
  std::unique_ptr<RayQuery> oracleRays;
  double typicalBuilding = 16.0;  // metres: median horizontal size of small objects
};

// Takes the scene; builds the rest (logs the occluders at info level): the
// static world up to `parts`, and the oracle's rays only when `oracle`
// (comparePvsWithTruth needs them).
PvsWorld makePvsWorld(Scene scene, bool oracle = true,
                      StaticWorldParts parts = StaticWorldParts::FreeSpace);

// Ground-truth options for a cell of `w`: `points` viewpoints, `resolution`
// rays per cube-face side, leaving out the viewpoints the PVS contract does
// not serve (inside solids). Keeps a reference to `w`.
SampledVisibilityOptions groundTruthOptions(const PvsWorld& w, size_t points, int resolution);

// One cell's PVS against its sampled ground truth. The truth aims probes at
// every PVS face (`probes` points a triangle; 0: the cube maps alone).
struct PvsTruth {
  SampledVisibility truth;
  std::vector<uint32_t> missing;      // seen but not in the PVS: a conservative PVS has none
  std::vector<uint32_t> unseenFaces;  // in the PVS, not sampled as seen (sorted)
  size_t pvsFaces = 0;
  // PVS faces not sampled as seen, by distance from the cell (kDistanceBands
  // upper bounds, the last open) and by how they face: up (roofs), sideways
  // (walls), down.
  static constexpr std::array<float, 5> kDistanceBands{25.0f, 50.0f, 100.0f, 200.0f, 400.0f};
  std::array<size_t, kDistanceBands.size() + 1> unseenByDistance{};
  size_t unseenUp = 0, unseenSide = 0, unseenDown = 0;
  size_t unseen() const { return unseenUp + unseenSide + unseenDown; }
  // The limits of distance band b of unseenByDistance (metres; the last
  // band's upper limit is infinity).
  static std::pair<float, float> band(size_t b);
  double pvsOverSeen() const;  // 0 when nothing is seen
  nlohmann::json toJson() const;
};

struct TruthOptions {
  size_t points = 24;    // viewpoints
  int resolution = 128;  // rays per cube-face side
  int probes = 8;        // points aimed at per triangle of a PVS face (0: none)
};

// Requires w.oracleRays.
PvsTruth comparePvsWithTruth(const PvsWorld& w, const Box3f& cell,
                             const std::vector<uint32_t>& pvsFaces, const TruthOptions& options);

}  // namespace vistream
