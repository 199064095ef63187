// One scene made ready for impostor bakes: its static triangles with their
// baked colours (the lighting cache, as the server streams them), its
// backdrop and ground decision, and the ε-PVS with the server's occlusion
// horizons, so a view cell's impostors replace exactly the far field of the
// PVS the server would stream.
//
// bakeCell: the PVS of the cell, the placement (impostor_placement.h), then
// one bake a site (impostor_bake.h). A site whose box reaches the cell, or
// whose impostor would cost more than maxBytesRatio times its geometry, is
// refused and left to geometry (its reason in `refused`, its faces in
// `geometryFaces`); every other failure propagates.
//
// Thread safety: immutable after construction; bakeCell may run from several
// threads (each bake uses TBB inside).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/light/lighting.h"
#include "common/scene/scene.h"
#include "common/world/static_world.h"
#include "protocol/geometry/geometry_codec.h"
#include "server/impostor/impostor_bake.h"
#include "server/impostor/impostor_placement.h"

namespace vistream {

class EpsilonPvs;
class HorizonFusion;

struct ImpostorWorldOptions {
  GroundChoice ground;
  LightingOptions lighting;
  std::filesystem::path lightingCache;  // empty: bake the lighting without a cache
};

struct CellImpostors {
  Box3f cell;
  size_t pvsTriangles = 0;
  // Per impostor: the faces it replaces and what they cost as geometry.
  std::vector<std::vector<uint32_t>> replacedFaces;
  std::vector<size_t> geometryBytes;
  ImpostorPlacement placement;
  std::vector<Impostor> impostors;  // one a baked site, in placement order
  std::vector<ImpostorStats> stats;
  std::vector<uint32_t> siteOf;      // per impostor: its index in placement.sites
  std::vector<std::string> refused;  // per refused site: why
  // The faces of the refused sites (those with any triangle in one),
  // ascending: far field the cell needs as geometry, since it has no impostor.
  std::vector<uint32_t> geometryFaces;
  double pvsSeconds = 0.0, seconds = 0.0;
};

class ImpostorWorld {
 public:
  ImpostorWorld(const Scene& scene, const ImpostorWorldOptions& options);
  ~ImpostorWorld();

  const Scene& scene() const { return scene_; }
  const FlatTriangles& triangles() const { return *world_.triangles; }
  ImpostorScene view() const;
  const Backdrop& backdrop() const { return backdrop_; }
  // The cell's PVS as indices into triangles() (the ε-PVS with horizons
  // where the scene has solid columns, back faces culled: the server's).
  std::vector<uint32_t> pvsTriangles(const Box3f& cell, double* seconds = nullptr) const;
  CellImpostors bakeCell(const Box3f& cell, const ImpostorPlacementOptions& placement,
                         const ImpostorOptions& options) const;
  // The same with the cell's PVS given (face IDs, as a PVS database holds it).
  CellImpostors bakeCell(const Box3f& cell, const std::vector<uint32_t>& pvsFaces,
                         const ImpostorPlacementOptions& placement,
                         const ImpostorOptions& options) const;
  // The triangles (indices into triangles()) of the given faces.
  std::vector<uint32_t> trianglesOfFaces(const std::vector<uint32_t>& faces) const;
  // The faces an impostor of `triangles` (indices into triangles()) replaces:
  // those whose every triangle is among them (a face reaching out of the
  // impostor stays geometry), ascending.
  std::vector<uint32_t> replacedFaces(const std::vector<uint32_t>& triangles) const;
  // The faces with any triangle among `triangles`, ascending.
  std::vector<uint32_t> facesTouching(const std::vector<uint32_t>& triangles) const;
  // What streaming those faces costs: one Geometry message as the server
  // encodes it (with their baked colours), framed.
  size_t geometryBytes(const std::vector<uint32_t>& faces) const;

 private:
  const Scene& scene_;
  StaticWorld world_;
  LightingGrid lighting_;
  Backdrop backdrop_;
  std::unique_ptr<HorizonFusion> horizons_;
  std::unique_ptr<EpsilonPvs> pvs_;
  // Face ID -> its triangles in triangles() (CSR).
  std::vector<uint32_t> faceFirst_, faceTriangles_;
  std::vector<wire::FaceTriangles> faces_;  // as the server streams them
  wire::QuantizationGrid grid_;
};

}  // namespace vistream
