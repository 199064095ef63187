#include "server/cmd/pvs_truth.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

#include "common/core/check.h"
#include "common/core/median.h"
#include "common/core/timer.h"
#include "common/world/sealed_surface.h"

namespace vistream {

PvsWorld makePvsWorld(Scene scene, bool oracle, StaticWorldParts parts) {
  PvsWorld w;
  w.scene = std::move(scene);
  StaticWorldOptions options;
  options.parts = parts;
  w.statics = buildStaticWorld(w.scene, options);
  if (oracle)
    w.oracleRays = makeSealedRayQuery(*w.statics.triangles, SolidsOptions{}.weldTolerance);
  Stopwatch sw;
  w.pvs = std::make_unique<EpsilonPvs>(w.scene, OccluderOptions{}, &w.statics);
  spdlog::info("{} occluders ({} solids, {} polygons), prepared in {:.0f} ms",
               w.pvs->occluders().occluders.size(), w.pvs->occluders().stats.solids,
               w.pvs->occluders().stats.polygons, sw.ms());
  std::vector<double> sizes;
  for (const Object& o : w.scene.objects) {
    const glm::vec3 e = o.bounds.extent();
    if (o.mesh.triangleCount() <= 200 && e.x < 200 && e.z < 200) sizes.push_back(0.5 * (e.x + e.z));
  }
  if (!sizes.empty()) w.typicalBuilding = median(sizes);
  return w;
}

SampledVisibilityOptions groundTruthOptions(const PvsWorld& w, size_t points, int resolution) {
  SampledVisibilityOptions gt;
  gt.points = points;
  gt.resolution = resolution;
  gt.skipViewpoint = [&w](const glm::vec3& p) {
    return w.statics.solids.unservedViewpoint(*w.statics.rays, p);
  };
  return gt;
}

double PvsTruth::pvsOverSeen() const {
  return truth.faces.empty() ? 0.0 : double(pvsFaces) / double(truth.faces.size());
}

std::pair<float, float> PvsTruth::band(size_t b) {
  return {b == 0 ? 0.0f : kDistanceBands[b - 1],
          b < kDistanceBands.size() ? kDistanceBands[b] : std::numeric_limits<float>::infinity()};
}

nlohmann::json PvsTruth::toJson() const {
  nlohmann::json bands = nlohmann::json::array();
  for (size_t b = 0; b < unseenByDistance.size(); ++b) {
    const auto [from, to] = band(b);
    bands.push_back({{"from_m", from},
                     {"to_m", std::isinf(to) ? nlohmann::json(nullptr) : nlohmann::json(to)},
                     {"faces", unseenByDistance[b]}});
  }
  return {{"seen_faces", truth.faces.size()},
          {"seen_by_probes_only", truth.probeOnly},
          {"viewpoints", truth.viewpoints},
          {"viewpoints_inside_solids", truth.insideSolid},
          {"rays", truth.rays},
          {"pvs_over_seen", pvsOverSeen()},
          {"missing_faces", missing},
          {"unseen_faces", unseen()},
          {"unseen_face_ids", unseenFaces},
          {"unseen_by_distance", bands},
          {"unseen_facing", {{"up", unseenUp}, {"side", unseenSide}, {"down", unseenDown}}},
          {"ms", truth.timeMs}};
}

PvsTruth comparePvsWithTruth(const PvsWorld& w, const Box3f& cell,
                             const std::vector<uint32_t>& pvsFaces, const TruthOptions& options) {
  VS_CHECK(w.oracleRays);
  std::vector<uint32_t> pvs = pvsFaces;
  std::sort(pvs.begin(), pvs.end());
  pvs.erase(std::unique(pvs.begin(), pvs.end()), pvs.end());
  SampledVisibilityOptions gt = groundTruthOptions(w, options.points, options.resolution);
  if (options.probes > 0) {
    gt.probeFaces = pvs;
    gt.probeSamples = options.probes;
  }
  PvsTruth r;
  r.pvsFaces = pvs.size();
  const FlatTriangles& tris = *w.statics.triangles;
  r.truth = sampleVisibleFaces(*w.oracleRays, tris, cell, gt);
  std::set_difference(r.truth.faces.begin(), r.truth.faces.end(), pvs.begin(), pvs.end(),
                      std::back_inserter(r.missing));
  // Per unseen PVS face: its nearest triangle's distance, and the facing of
  // its largest triangle.
  std::set_difference(pvs.begin(), pvs.end(), r.truth.faces.begin(), r.truth.faces.end(),
                      std::back_inserter(r.unseenFaces));
  const std::vector<uint32_t>& unseen = r.unseenFaces;
  struct Face {
    float distance = std::numeric_limits<float>::infinity();
    float area = -1.0f;
    float normalY = 0.0f;
  };
  std::vector<Face> faces(unseen.size());
  for (size_t t = 0; t < tris.size(); ++t) {
    const auto it = std::lower_bound(unseen.begin(), unseen.end(), tris.faceIds[t]);
    if (it == unseen.end() || *it != tris.faceIds[t]) continue;
    Face& f = faces[size_t(it - unseen.begin())];
    f.distance = std::min(f.distance, cell.distanceTo(tris.triangleBounds(t)));
    const glm::vec3 n =
        glm::cross(tris.vertex(t, 1) - tris.vertex(t, 0), tris.vertex(t, 2) - tris.vertex(t, 0));
    const float area = glm::length(n);
    if (area > f.area) {
      f.area = area;
      f.normalY = area > 0.0f ? n.y / area : 0.0f;
    }
  }
  for (const Face& f : faces) {
    const auto band = std::upper_bound(PvsTruth::kDistanceBands.begin(),
                                       PvsTruth::kDistanceBands.end(), f.distance);
    ++r.unseenByDistance[size_t(band - PvsTruth::kDistanceBands.begin())];
    (f.normalY > 0.7f ? r.unseenUp : f.normalY < -0.7f ? r.unseenDown : r.unseenSide) += 1;
  }
  return r;
}

}  // namespace vistream
