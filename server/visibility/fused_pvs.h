// A conservative PVS with occluder fusion: the method of Wonka, Wimmer and
// Schmalstieg, "Visibility Preprocessing with Occluder Fusion for Urban
// Walkthroughs" (EGWR 2000), on top of the single-occluder PVS of Cohen-Or
// and Zadicario 1998.
//
// Every solid occluder is shrunk (eroded) by epsilon. Points are sampled on
// the boundary of the view cell so that every boundary point lies within
// epsilon of a sample; a viewpoint inside the cell sees nothing its exit
// point on the boundary does not. From each sample the eroded occluders are
// drawn into a conservative occlusion cube map: a pixel counts as covered only
// if all four corner rays pass through one occluder's interior (the cone of a
// convex occluder is convex, so the whole pixel is covered), and it keeps an
// upper bound of the distance at which its rays are blocked. A face is hidden
// from the sample if every pixel its cone can touch is covered nearer than the
// face's nearest point. Hidden from an eroded occluder at p means hidden from
// every point within epsilon of p by the original one (Wonka et al., section
// 4), so hidden from all samples means hidden from the whole cell. Several
// occluders can cover one face's pixels together: that is the fusion the
// paper's method lacks.
//
// The result is intersected with the single-occluder PVS, which is just as
// conservative, so it is never larger. Polygon occluders (zero thickness)
// cannot be eroded and take part only through the single-occluder PVS.
//
// Accuracy knobs: epsilon (smaller erodes less but needs more samples) and
// the cube-map resolution. Thread safety: compute() is const.
#pragma once

#include <vector>

#include "server/visibility/epsilon_pvs.h"

namespace vistream {

struct FusedPvsOptions {
  double epsilon = 0.5;  // metres of erosion = maximum distance from a cell point to a sample
  int resolution = 96;   // cube-map pixels per face side
};

struct FusedPvsStats {
  size_t samples = 0;
  size_t erodedOccluders = 0;
  size_t candidateFaces = 0;  // faces of the single-occluder PVS tested
  size_t fusedCulled = 0;     // of those, hidden by fused occluders
  double timeMs = 0.0;

  // Every field above, once (common/core/stats_fields.h).
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"samples", "samples", ""}, samples);
    f(StatField{"eroded_occluders", "eroded occluders", ""}, erodedOccluders);
    f(StatField{"candidate_faces", "candidate faces", ""}, candidateFaces);
    f(StatField{"fused_culled", "culled by fused occluders", ""}, fusedCulled);
    f(StatField{"time_ms", "time", "ms"}, timeMs);
  }
};
static_assert(sizeof(FusedPvsStats) == 5 * 8,
              "FusedPvsStats changed: update FusedPvsStats::forEachField");

class FusedPvs {
 public:
  FusedPvs(const EpsilonPvs& base, const FusedPvsOptions& options = {});

  // The PVS of `cell` (local frame); stats.timeMs includes the base PVS.
  PvsResult compute(const Box3f& cell, const PvsOptions& baseOptions = {},
                    FusedPvsStats* fused = nullptr) const;

  const FusedPvsOptions& options() const { return options_; }

 private:
  struct ErodedSolid {
    std::vector<glm::dvec4> planes;    // dot(n, x) < d
    std::vector<glm::dvec3> vertices;  // of the eroded polytope
  };
  const EpsilonPvs& base_;
  FusedPvsOptions options_;
  std::vector<ErodedSolid> solids_;
};

}  // namespace vistream
