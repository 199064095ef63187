// Occluder fusion for cities: 2.5D occlusion horizons over a conservative
// height field of solid columns. The method is that of Wonka, Wimmer and
// Schmalstieg, "Visibility Preprocessing with Occluder Fusion for Urban
// Walkthroughs" (EGWR 2000: occluder shrinking by epsilon, point samples
// within epsilon of every viewpoint, sections 4-5), with the per-point
// occlusion horizon of Downs, Moeller and Sequin, "Occlusion Horizons for
// Driving through Urban Scenery" (I3D 2001, section 3) in place of their
// cull map. The proof of conservativeness is at the top of horizon_fusion.cpp.
//
// It is a stage after the single-occluder PVS (epsilon_pvs.h): given a cell
// and the sorted faces that survived it, it removes the faces that several
// solids hide together (a row of buildings, a wall and the next wall).
//
// What occludes: columns of an X/Z grid (side gridSize metres) whose box
// [base, top] no triangle touches and which lie inside an enclosure of the
// static geometry (common/world/solids.h): a welded parity group, its
// dangling sheets peeled, that is a cycle modulo 2 (either winding; row
// houses whose party walls are left out close up together) or one open only
// at its base (LoD2 buildings without a ground surface), above its floor.
// Corners are welded and T-junctions cut within the weld tolerance, so
// cracks narrower than that are taken as closed. Groups with a real hole
// above the base (a missing wall or roof) never occlude here; they still
// take part through the single-occluder PVS. An enclosure whose floor is
// not below the cell does not occlude anything for that cell.
// Vertical walls occlude too, solid or not (wall_occluders.h: upright
// triangles grouped by plane, the heights their union covers along it),
// each eroded along its own line by the shrinking radius over the sine of
// the angle a horizon's ray crosses it at; the open meshes of real city
// models (row blocks whose walls leave slits from the base up) occlude
// only this way.
//
// Frames and units: the scene's local frame, metres, Y up. The cell is a
// closed axis-aligned box; the result is valid for every viewpoint in it
// that the PVS contract serves (Solids::unservedViewpoint: not inside a
// solid or an enclosure, nor on a closed one's surface; a cell that cuts
// into a building is served outside it), in every direction.
// Dynamic objects never occlude and their faces are never removed.
//
// Thread safety: cull() is const and may run concurrently. Bad input: a
// candidate face ID the scene does not have is kept; an empty or non-finite
// cell is a caller's bug (VS_CHECK).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "common/core/stats_fields.h"
#include "common/scene/scene.h"
#include "common/world/static_world.h"

namespace vistream {

struct HorizonFusionOptions {
  // Metres: every point of the cell's top face lies within epsilon of a
  // sample, and occluders are shrunk by it. Larger: fewer samples (faster),
  // thinner occluders.
  double epsilon = 1.0;
  // Metres: side of a height-field column. The grid grows coarser on large
  // scenes so that it holds at most kMaxColumns columns.
  double gridSize = 0.5;
  // Azimuth bins of each occlusion horizon (a power of two is not needed).
  int azimuthBins = 1024;
  // Metres of extra shrinking that lets one ray per azimuth bin stand for the
  // whole bin: a horizon reaches 2 * binMargin / (2 pi / azimuthBins) metres
  // (163 m with the defaults); nothing farther occludes. Shrinking is
  // rounded up to whole columns, so epsilon + binMargin = 1.5 m costs no more
  // than 1.25 m on the 0.5 m grid. Defaults tuned on city1 (4 m street cells):
  // 2048 bins with a 0.25 m margin cull the same faces in twice the time, and
  // epsilon 0.5 m (36 samples instead of 9) culls 1-3% more in 3-4x the time.
  double binMargin = 0.5;
  // Levels of finer bins tried where a bin does not hide its part of a face:
  // each level splits every bin into kRefine and reaches kRefine times
  // farther with the same shrinking (a street whose far end opens onto a
  // square hidden by buildings 300 m away). Traced lazily, only for the bins
  // that need them. 0: azimuthBins only.
  int refinements = 1;
  // Walks pass blocks and super-blocks of columns that cannot raise their
  // horizon, and runs of empty blocks, without reading their columns. The
  // steps are the same either way up to the last bits of their distances (a
  // jump recomputes the distance to the next column sides where the walk
  // adds them up); false reads every column (for tests and as the
  // benchmark's baseline).
  bool skipBlocks = true;
  // Before walking a bin from a sample, read only the piece of it around the
  // distance where a step last hid a face in it (an earlier sample's walk):
  // a hide found there is proven like any other (proof, step 6), and a face
  // the piece does not hide gets the whole walk, so the hints only add
  // culled faces. Which ones can depend on the order the candidates are
  // tested in (cull() takes them in the order given; the PVS gives them
  // sorted by face ID), never on threads. false: every query walks from the
  // sample (for tests and as the benchmark's baseline).
  bool hidingHints = true;
  // Vertical walls occlude too, each eroded along its own line by the
  // shrinking radius over the sine of the angle a horizon's ray meets it at
  // (proof, step 7): the walls of open meshes (row blocks whose walls leave
  // slits, facades without a back), which make no solid columns, and walls
  // thinner than twice the shrinking. false: solid columns only.
  bool walls = true;
  // Where a wall's erosion runs off its end at a corner, the walls joined
  // there go on as one chain that must cross the horizon's strip from side
  // to side (proof, step 8): the corners of open buildings seen from the
  // street. false: each wall line alone. Needs `walls`.
  bool wallChains = true;
};

struct HorizonFusionStats {
  double timeMs = 0.0;
  size_t candidateFaces = 0;  // faces given
  size_t culled = 0;          // of those, hidden from every sample
  size_t samples = 0;         // points on the cell's top face
  size_t excludedSolids = 0;  // enclosures whose floor the cell reaches: they occlude nothing
  uint64_t columnSteps = 0;   // height-field columns walked by the horizons
  uint64_t horizonBins = 0;   // azimuth bins traced (lazily, only where a face needs one)
  uint64_t wallSteps = 0;     // horizon steps made by walls (proof, step 7)
  uint64_t chainSteps = 0;    // by chains of walls joined at corners (step 8)

  // Every field above, once (common/core/stats_fields.h).
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"time_ms", "time", "ms"}, timeMs);
    f(StatField{"candidate_faces", "candidate faces", ""}, candidateFaces);
    f(StatField{"culled", "culled by fused horizons", ""}, culled);
    f(StatField{"samples", "samples", ""}, samples);
    f(StatField{"excluded_solids", "enclosures reaching below the cell", ""}, excludedSolids);
    f(StatField{"column_steps", "columns walked", ""}, columnSteps);
    f(StatField{"horizon_bins", "azimuth bins traced", ""}, horizonBins);
    f(StatField{"wall_steps", "horizon steps made by walls", ""}, wallSteps);
    f(StatField{"chain_steps", "horizon steps made by chains of walls", ""}, chainSteps);
  }
};
static_assert(sizeof(HorizonFusionStats) == 9 * 8,
              "HorizonFusionStats changed: update HorizonFusionStats::forEachField");

struct HorizonFusionResult {
  std::vector<uint32_t> faces;  // sorted: the candidates not proven hidden
  HorizonFusionStats stats;
};

class HorizonFusion {
 public:
  static constexpr int kRefine = 4;  // bins per bin of the previous level
  // Upper bound on height-field columns (memory: 8 bytes each).
  static constexpr size_t kMaxColumns = size_t(16) << 20;

  // Builds the height field of the scene's static geometry (seconds on a
  // city). The scene must outlive this object. Options must be positive and
  // finite (VS_CHECK).
  explicit HorizonFusion(const Scene& scene, const HorizonFusionOptions& options = {});
  // The same over a static world already built for the scene (its
  // triangles, ray query and solids: StaticWorldParts::Solids or more),
  // which must outlive this object.
  HorizonFusion(const Scene& scene, const StaticWorld& world,
                const HorizonFusionOptions& options = {});
  ~HorizonFusion();
  HorizonFusion(const HorizonFusion&) = delete;
  HorizonFusion& operator=(const HorizonFusion&) = delete;

  // `cell` in the local frame; `candidates` sorted face IDs (typically the
  // single-occluder PVS). Returns the candidates not proven hidden.
  HorizonFusionResult cull(const Box3f& cell, std::span<const uint32_t> candidates) const;

  const HorizonFusionOptions& options() const { return options_; }
  double gridSize() const;      // metres, after the kMaxColumns rule
  size_t solidColumns() const;  // columns that occlude before shrinking
  size_t wallLines() const;     // lines of vertical walls that occlude (0 without walls)
  double prepareMs() const { return prepareMs_; }

 public:
  struct Impl;  // the height field and the scene's triangles, solids and faces

 private:
  HorizonFusion(const Scene& scene, std::unique_ptr<const StaticWorld> owned,
                const StaticWorld* borrowed, const HorizonFusionOptions& options);

  std::unique_ptr<Impl> impl_;
  HorizonFusionOptions options_;
  double prepareMs_ = 0.0;
};

// Whether a PVS runs the occlusion horizons (`--fusion` of the bake and the
// server): Auto builds them and keeps them only where the scene has solid
// columns (cities and terrain; not interiors, whose rooms are no solids).
enum class FusionChoice : uint8_t { Auto, Horizons, None };
// "auto", "horizons" or "none"; nothing for any other text.
std::optional<FusionChoice> parseFusionChoice(const std::string& text);
// The horizons a choice asks for, or null; logs their size and build time.
// With `world` (parts Solids or more) they share its triangles, rays and
// solids, which must outlive them.
std::unique_ptr<HorizonFusion> makeHorizonFusion(const Scene& scene, FusionChoice choice,
                                                 const StaticWorld* world = nullptr);

}  // namespace vistream
