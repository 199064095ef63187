#include "server/impostor/impostor_world.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>

#include "common/core/error.h"
#include "common/core/timer.h"
#include "common/light/lighting_cache.h"
#include "protocol/geometry/scene_faces.h"
#include "protocol/wire/messages.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/horizon_fusion.h"

namespace vistream {

ImpostorWorld::ImpostorWorld(const Scene& scene, const ImpostorWorldOptions& options)
    : scene_(scene) {
  StaticWorldOptions worldOptions;
  worldOptions.ground = options.ground;
  worldOptions.parts = StaticWorldParts::Ground;
  world_ = buildStaticWorld(scene, worldOptions);
  SceneLighting lit = lightScene(scene, *world_.triangles, options.lighting, options.lightingCache,
                                 /*progress=*/true);
  lighting_ = std::move(lit.load.grid);
  backdrop_ = lit.backdrop;
  horizons_ = makeHorizonFusion(scene, FusionChoice::Auto);
  pvs_ = std::make_unique<EpsilonPvs>(scene);
  pvs_->setFusion(horizons_.get());

  faces_ = wire::sceneFaces(scene, &lighting_);
  grid_ = wire::QuantizationGrid::forBounds(scene.bounds());

  const FlatTriangles& t = *world_.triangles;
  faceFirst_.assign(size_t(scene.faceCount) + 1, 0);
  for (uint32_t id : t.faceIds)
    if (id < scene.faceCount) ++faceFirst_[id + 1];
  for (size_t f = 0; f < scene.faceCount; ++f) faceFirst_[f + 1] += faceFirst_[f];
  faceTriangles_.resize(faceFirst_.back());
  std::vector<uint32_t> next(faceFirst_.begin(), faceFirst_.end() - 1);
  for (uint32_t k = 0; k < t.size(); ++k)
    if (t.faceIds[k] < scene.faceCount) faceTriangles_[next[t.faceIds[k]]++] = k;
}

ImpostorWorld::~ImpostorWorld() = default;

ImpostorScene ImpostorWorld::view() const {
  return ImpostorScene{*world_.triangles, *world_.rays, lighting_, backdrop_, world_.ground.y};
}

std::vector<uint32_t> ImpostorWorld::trianglesOfFaces(const std::vector<uint32_t>& faces) const {
  std::vector<uint32_t> out;
  for (uint32_t f : faces)
    if (f < scene_.faceCount)
      out.insert(out.end(), faceTriangles_.begin() + faceFirst_[f],
                 faceTriangles_.begin() + faceFirst_[f + 1]);
  return out;
}

std::vector<uint32_t> ImpostorWorld::pvsTriangles(const Box3f& cell, double* seconds) const {
  Stopwatch watch;
  const PvsResult r = pvs_->compute(cell);
  std::vector<uint32_t> out = trianglesOfFaces(r.faces);
  if (seconds) *seconds = watch.ms() / 1000.0;
  return out;
}

namespace {

CellImpostors bakeSites(const ImpostorWorld& world, const Box3f& cell,
                        const std::vector<uint32_t>& pvs, const ImpostorPlacementOptions& placement,
                        const ImpostorOptions& options, CellImpostors out) {
  Stopwatch watch;
  out.cell = cell;
  out.pvsTriangles = pvs.size();
  out.placement = placeImpostors(cell, world.triangles(), pvs, placement);
  for (uint32_t s = 0; s < out.placement.sites.size(); ++s) {
    const ImpostorSite& site = out.placement.sites[s];
    try {
      std::vector<uint32_t> faces = world.replacedFaces(site.triangles);
      const size_t geometryBytes = world.geometryBytes(faces);
      const bool capped = placement.maxBytesRatio > 0.0f;
      const double budget = double(placement.maxBytesRatio) * double(geometryBytes);
      ImpostorStats stats;
      // The budget stops a costly bake before its appearance, the most of
      // its time; the whole encoding is weighed once made.
      std::optional<Impostor> impostor =
          bakeImpostorWithin(world.view(), cell, site.box, site.triangles, options,
                             capped ? std::max<uint64_t>(1, uint64_t(budget)) : 0, &stats);
      if (!impostor || (capped && double(stats.bytes) > budget)) {
        const std::string why =
            impostor
                ? fmt::format(
                      "sector {} band {}: {} bytes as an impostor against {} as "
                      "geometry (more than {}x)",
                      site.sector, site.band, stats.bytes, geometryBytes, placement.maxBytesRatio)
                : fmt::format(
                      "sector {} band {}: its points' positions alone take {} bytes "
                      "against {} as geometry (more than {}x)",
                      site.sector, site.band, stats.positionBytes, geometryBytes,
                      placement.maxBytesRatio);
        spdlog::info("impostor left as geometry: {}", why);
        out.refused.push_back(why);
        continue;
      }
      out.impostors.push_back(std::move(*impostor));
      out.stats.push_back(stats);
      out.siteOf.push_back(s);
      out.replacedFaces.push_back(std::move(faces));
      out.geometryBytes.push_back(geometryBytes);
    } catch (const InputError& e) {
      spdlog::warn("impostor of sector {} band {} left as geometry: {}", site.sector, site.band,
                   e.what());
      out.refused.push_back(e.what());
    }
  }
  // The refused sites: those without an impostor.
  std::vector<bool> baked(out.placement.sites.size(), false);
  for (uint32_t s : out.siteOf) baked[s] = true;
  std::vector<uint32_t> refusedTriangles;
  for (size_t s = 0; s < out.placement.sites.size(); ++s)
    if (!baked[s])
      refusedTriangles.insert(refusedTriangles.end(), out.placement.sites[s].triangles.begin(),
                              out.placement.sites[s].triangles.end());
  out.geometryFaces = world.facesTouching(refusedTriangles);
  if (!out.placement.sites.empty())
    out.placement.why =
        (out.refused.empty()
             ? fmt::format("{} impostors", out.impostors.size())
             : fmt::format("{} impostors, {} sites left as geometry ({})", out.impostors.size(),
                           out.refused.size(), out.refused.front())) +
        "; " + out.placement.why;
  out.seconds = watch.ms() / 1000.0 + out.pvsSeconds;
  return out;
}

}  // namespace

CellImpostors ImpostorWorld::bakeCell(const Box3f& cell, const ImpostorPlacementOptions& placement,
                                      const ImpostorOptions& options) const {
  CellImpostors out;
  const std::vector<uint32_t> pvs = pvsTriangles(cell, &out.pvsSeconds);
  return bakeSites(*this, cell, pvs, placement, options, std::move(out));
}

CellImpostors ImpostorWorld::bakeCell(const Box3f& cell, const std::vector<uint32_t>& pvsFaces,
                                      const ImpostorPlacementOptions& placement,
                                      const ImpostorOptions& options) const {
  return bakeSites(*this, cell, trianglesOfFaces(pvsFaces), placement, options, CellImpostors{});
}

std::vector<uint32_t> ImpostorWorld::replacedFaces(const std::vector<uint32_t>& triangles) const {
  std::vector<uint32_t> faces;
  faces.reserve(triangles.size());
  for (uint32_t k : triangles) faces.push_back(world_.triangles->faceIds[k]);
  std::sort(faces.begin(), faces.end());
  std::vector<uint32_t> out;
  for (size_t i = 0; i < faces.size();) {
    size_t j = i;
    while (j < faces.size() && faces[j] == faces[i]) ++j;
    const uint32_t f = faces[i];
    // Triangle indices are distinct, so a face is whole when it was met as
    // often as it has triangles.
    if (f < scene_.faceCount && j - i == faceFirst_[f + 1] - faceFirst_[f]) out.push_back(f);
    i = j;
  }
  return out;
}

std::vector<uint32_t> ImpostorWorld::facesTouching(const std::vector<uint32_t>& triangles) const {
  std::vector<uint32_t> faces;
  faces.reserve(triangles.size());
  for (uint32_t k : triangles)
    if (world_.triangles->faceIds[k] < scene_.faceCount)
      faces.push_back(world_.triangles->faceIds[k]);
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  return faces;
}

size_t ImpostorWorld::geometryBytes(const std::vector<uint32_t>& faces) const {
  if (faces.empty()) return 0;
  std::vector<wire::FaceTriangles> batch;
  batch.reserve(faces.size());
  for (uint32_t f : faces) batch.push_back(faces_.at(f));
  return wire::encodeMessage(wire::encodeGeometry(batch, grid_)).size();
}

}  // namespace vistream
