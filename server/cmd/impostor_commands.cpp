#include "server/cmd/impostor_commands.h"

#include <fmt/format.h>
#include <tbb/global_control.h>

#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "common/cmd/cli.h"
#include "common/core/error.h"
#include "common/core/parse.h"
#include "common/core/progress.h"
#include "common/core/stats_output.h"
#include "common/core/timer.h"
#include "common/generate/scene_spec.h"
#include "server/cmd/mpi_bake.h"
#include "server/cmd/scene_boxes.h"
#include "server/impostor/impostor_database.h"
#include "server/impostor/impostor_world.h"

namespace vistream {

using nlohmann::json;

struct ImpostorCommand::Arguments {
  std::string scene, cell, texture = "8x2", screen = "640x480", db, out, cells, shard;
  unsigned threads = 0;
  uint32_t mergeCells = ImpostorBakeOptions{}.mergeCells;
  bool json = false, noRemoval = false, noThinning = false, keepHidden = false, mpi = false;
  GroundChoice ground;
  std::filesystem::path lightingCache;
  ImpostorPlacementOptions placement;
  ImpostorOptions bake;
};

ImpostorCommand::ImpostorCommand(CLI::App& app, SceneLimits& limits)
    : limits_(limits), a_(std::make_unique<Arguments>()) {
  Arguments& a = *a_;
  sub_ = app.add_subcommand(
      "impostors",
      "point-based impostors of a view cell's far field (Wimmer 2001, chapter 5): placement, "
      "three-LDI sampling, point removal, Monte Carlo appearance textures");
  sub_->add_option("--scene", a.scene, "SCENE")->required();
  sub_->add_option("--cell", a.cell,
                   "x0,y0,z0,x1,y1,z1: bake this view cell's impostors and report them (file "
                   "coordinates)");
  sub_->add_option("--db", a.db, "bake every cell of this PVS database (with --out)");
  sub_->add_option("--out,-o", a.out, "the impostor database to write (with --db)");
  sub_->add_option("--cells", a.cells,
                   "with --db: only the cells overlapping this box, x0,y0,z0,x1,y1,z1 (file "
                   "coordinates)");
  sub_->add_option("--threads", a.threads, "worker threads (0: all cores)")
      ->check(atLeast<unsigned>(0));
  sub_->add_option("--shard", a.shard,
                   "with --db: bake only shard i/n of the cells (join shards with impostor-merge)");
  sub_->add_flag("--mpi", a.mpi,
                 "with --db: run as one rank of an MPI job (mpirun -n N vistream-pvs impostors "
                 "--mpi ...): rank i of n bakes shard i/n, rank 0 merges them into --out");
  sub_->add_flag("--json", a.json,
                 "one JSON object on stdout: with --cell, impostors (points, screen_pixels, "
                 "points_per_pixel, bytes, bake_s, ...) and stats; with --db, the bake's figures");
  // Placement (impostor_placement.h).
  sub_->add_option("--near-distance", a.placement.nearDistance,
                   "d: the client's near field; impostors hold the PVS beyond it (metres)")
      ->capture_default_str()
      ->check(positive());
  sub_->add_option("--sectors", a.placement.sectors, "azimuth sectors around the cell")
      ->capture_default_str()
      ->check(inRange<uint32_t>(1, 64));
  sub_->add_option("--bands", a.placement.bands, "distance bands [d,2d), [2d,4d), ...")
      ->capture_default_str()
      ->check(inRange<uint32_t>(1, 16));
  sub_->add_option("--min-triangles", a.placement.minTriangles,
                   "a lighter sector and band stays geometry")
      ->capture_default_str()
      ->check(atLeast<size_t>(1));
  sub_->add_option("--max-bytes-ratio", a.placement.maxBytesRatio,
                   "an impostor costing more than this many times the Geometry bytes of the "
                   "faces it replaces stays geometry (0: no limit)")
      ->capture_default_str()
      ->check(nonNegative());
  sub_->add_option("--merge-cells", a.mergeCells,
                   "with --db: view cells of up to this many grid cells merged along a street "
                   "share one set of impostors (1: every cell its own)")
      ->capture_default_str()
      ->check(inRange<uint32_t>(1, 64));
  // Sampling and appearance (impostor_bake.h).
  sub_->add_option("--resolution", a.bake.resolutionFactor,
                   "LDI resolution factor (1: the thesis's heuristic)")
      ->capture_default_str()
      ->check(between(0.05, 8.0));
  sub_->add_flag("--no-removal", a.noRemoval, "keep points another camera samples better");
  sub_->add_flag("--no-thinning", a.noThinning,
                 "keep every point of a camera that samples its surface sqrt(2) times finer than "
                 "sufficient (point removal's checkerboard thinning)");
  sub_->add_flag("--keep-hidden", a.keepHidden, "keep points that no viewpoint in the cell sees");
  sub_->add_option("--visibility-views", a.bake.visibilityViews,
                   "viewpoints tried per point before it counts as hidden")
      ->capture_default_str()
      ->check(inRange<uint32_t>(1, 4096));
  sub_->add_option("--max-layers", a.bake.maxLayers, "LDI layers per pixel")
      ->capture_default_str()
      ->check(inRange<uint32_t>(1, 64));
  sub_->add_option("--texture", a.texture, "texels per point, WIDTHxHEIGHT (1x1: one colour)")
      ->capture_default_str();
  sub_->add_option("--variance", a.bake.varianceThreshold,
                   "Monte Carlo stops once a texel's standard error is below this (8-bit levels)")
      ->capture_default_str()
      ->check(positive());
  sub_->add_option("--pixel-filter", a.bake.pixelFilterSigma,
                   "the Gaussian (sigma, pixels) that widens each appearance ray's pixel box; "
                   "the thesis: about 0.5")
      ->capture_default_str()
      ->check(inRange<float>(0.0f, 4.0f));
  sub_->add_option("--min-rays", a.bake.minRays, "appearance rays per texel, at least")
      ->capture_default_str()
      ->check(inRange<uint32_t>(2, 1 << 16));
  sub_->add_option("--max-rays", a.bake.maxRays, "appearance rays per texel, at most")
      ->capture_default_str()
      ->check(inRange<uint32_t>(2, 1 << 16));
  sub_->add_option("--single-colour", a.bake.singleColourTolerance,
                   "a point whose texels all lie this close to their mean keeps one colour "
                   "(8-bit levels; 0: never)")
      ->capture_default_str()
      ->check(nonNegative());
  sub_->add_option("--position-error", a.bake.positionError,
                   "the most a point may move, in the screen's smallest pixel angle seen from "
                   "anywhere in the cell (the precision the encoding carries)")
      ->capture_default_str()
      ->check(inRange<float>(0.0f, 0.5f));
  sub_->add_option("--colour-step", a.bake.colourStep,
                   "textured points' texels snap to multiples of this many 8-bit levels "
                   "(single colours stay exact)")
      ->capture_default_str()
      ->check(CLI::IsMember({1u, 2u, 4u, 8u, 16u}));
  sub_->add_option("--screen", a.screen, "the viewer's screen the samples are sized for, WxH")
      ->capture_default_str();
  sub_->add_option("--fov", a.bake.screen.vfovDeg, "the viewer's vertical field of view (degrees)")
      ->capture_default_str()
      ->check(between(1.0, 170.0));
  sub_->add_option("--seed", a.bake.seed, "Monte Carlo seed")
      ->capture_default_str()
      ->check(atLeast<uint64_t>(0));
  addGroundOption(*sub_, a.ground);
  addLightingCacheOption(*sub_, a.lightingCache);
  addSceneLimitsOption(*sub_, limits_);
}

ImpostorCommand::~ImpostorCommand() = default;

bool ImpostorCommand::chosen() const {
  return sub_->parsed();
}

namespace {

json fileBoxJson(const Scene& scene, const Box3f& box) {
  const glm::dvec3 lo = scene.toFile(box.lo), hi = scene.toFile(box.hi);
  return {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z};
}

}  // namespace

// The bake's options as JSON, stored in the database (and its fingerprint).
std::string ImpostorCommand::settingsJson() const {
  const Arguments& a = *a_;
  const ImpostorOptions& o = a.bake;
  return json{{"near_distance", a.placement.nearDistance},
              {"sectors", a.placement.sectors},
              {"bands", a.placement.bands},
              {"min_triangles", a.placement.minTriangles},
              {"max_bytes_ratio", a.placement.maxBytesRatio},
              {"merge_cells", a.mergeCells},
              {"resolution", o.resolutionFactor},
              {"remove_points", o.removePoints},
              {"thin_points", o.thinOversampled},
              {"cull_hidden", o.cullHidden},
              {"visibility_views", o.visibilityViews},
              {"max_layers", o.maxLayers},
              {"texture", {o.textureWidth, o.textureHeight}},
              {"variance", o.varianceThreshold},
              {"pixel_filter", o.pixelFilterSigma},
              {"min_rays", o.minRays},
              {"max_rays", o.maxRays},
              {"single_colour", o.singleColourTolerance},
              {"position_error", o.positionError},
              {"colour_step", o.colourStep},
              {"screen", {o.screen.width, o.screen.height}},
              {"fov", o.screen.vfovDeg},
              {"seed", o.seed}}
      .dump();
}

ImpostorBakeReport ImpostorCommand::bakeShardOf(const Scene& scene, const PvsDatabase& pvs,
                                                const std::optional<Box3d>& fileCells,
                                                uint32_t shardIndex, uint32_t shardCount,
                                                const std::string& out, bool progress) const {
  const Arguments& a = *a_;
  ImpostorBakeOptions options;
  options.placement = a.placement;
  options.impostor = a.bake;
  options.threads = a.threads;
  options.mergeCells = a.mergeCells;
  options.settings = settingsJson();
  options.shardIndex = shardIndex;
  options.shardCount = shardCount;
  if (fileCells) {
    warnIfOutsideScene(scene, *fileCells, "--cells", a.cells);
    options.region = toLocal(scene, *fileCells);
  }
  std::unique_ptr<ProgressBar> bar;
  if (progress)
    options.progress = [&](size_t done, size_t total) {
      if (!bar) {
        bar = std::make_unique<ProgressBar>("baking impostors", total);
        bar->advance(done);
      } else {
        bar->advance(1);
      }
    };
  const ImpostorWorld world(scene, {a.ground, LightingOptions{}, a.lightingCache});
  const ImpostorBakeReport r = bakeImpostorDatabase(world, pvs, options, out);
  if (bar) bar->finish();
  return r;
}

int ImpostorCommand::bakeDatabase(const Scene& scene, const PvsDatabase& pvs,
                                  const std::optional<Box3d>& fileCells) {
  const Arguments& a = *a_;
  uint32_t shardIndex = 0, shardCount = 1;
  if (!a.shard.empty()) std::tie(shardIndex, shardCount) = parseShard(a.shard);
  const ImpostorBakeReport r =
      bakeShardOf(scene, pvs, fileCells, shardIndex, shardCount, a.out, /*progress=*/true);
  if (a.json) {
    std::cout << json{{"out", a.out},
                      {"cells", r.cells},
                      {"resumed_cells", r.resumedCells},
                      {"computed_cells", r.computedCells},
                      {"view_cells", r.viewCells},
                      {"cells_with_impostors", r.cellsWithImpostors},
                      {"view_cells_with_impostors", r.viewCellsWithImpostors},
                      {"impostors", r.impostors},
                      {"points", r.points},
                      {"bytes", r.bytes},
                      {"geometry_bytes", r.geometryBytes},
                      {"geometry_faces", r.geometryFaces},
                      {"time_ms", r.timeMs}}
                     .dump(2)
              << "\n";
    return 0;
  }
  fmt::print("baked impostors of {} -> {}\n", scene.name, a.out);
  fmt::print("  {:<28} {:>12}\n", "cells", r.cells);
  fmt::print("  {:<28} {:>12}\n", "resumed from journal", r.resumedCells);
  fmt::print("  {:<28} {:>12}\n", "computed", r.computedCells);
  fmt::print("  {:<28} {:>12}\n", "view cells (merged)", r.viewCells);
  fmt::print("  {:<28} {:>12}\n", "cells with impostors", r.cellsWithImpostors);
  fmt::print("  {:<28} {:>12}\n", "view cells with impostors", r.viewCellsWithImpostors);
  fmt::print("  {:<28} {:>12}\n", "impostors", r.impostors);
  fmt::print("  {:<28} {:>12}\n", "points", r.points);
  fmt::print("  {:<28} {:>12}\n", "bytes", r.bytes);
  fmt::print("  {:<28} {:>12}\n", "geometry bytes replaced", r.geometryBytes);
  fmt::print("  {:<28} {:>12}\n", "faces left as geometry", r.geometryFaces);
  fmt::print("  {:<28} {:>12.1f}\n", "time (s)", r.timeMs / 1000.0);
  return 0;
}

int ImpostorCommand::run() {
  Arguments& a = *a_;
  // Everything the arguments decide is checked before the scene loads.
  const bool oneCell = !a.cell.empty();
  if (oneCell == !a.db.empty())
    throwInputError(
        "--cell or --db: give one (--cell bakes one view cell and reports it, --db "
        "bakes every cell of a PVS database into --out)");
  if (!a.db.empty() && a.out.empty()) throwInputError("--out: required with --db");
  if (oneCell && (!a.out.empty() || !a.cells.empty() || !a.shard.empty() || a.mpi))
    throwInputError("--out, --cells, --shard and --mpi: only with --db");
  if (a.mpi && !a.shard.empty())
    throwInputError("--mpi gives each rank its shard (rank i of n bakes shard i/n): drop --shard");
  if (!a.shard.empty()) parseShard(a.shard);
  const Box3d fileCell = oneCell ? parseFileBox(a.cell, "--cell") : Box3d();
  std::optional<Box3d> fileCells;
  if (!a.cells.empty()) fileCells = parseFileBox(a.cells, "--cells");
  const WidthHeight texture = parseWidthHeight(a.texture, "--texture", 1, 64);
  a.bake.textureWidth = uint32_t(texture.width);
  a.bake.textureHeight = uint32_t(texture.height);
  const WidthHeight screen = parseWidthHeight(a.screen, "--screen", 16, 8192);
  a.bake.screen.width = screen.width;
  a.bake.screen.height = screen.height;
  if (a.bake.minRays > a.bake.maxRays)
    throwInputError("--min-rays {} exceeds --max-rays {}", a.bake.minRays, a.bake.maxRays);
  a.bake.removePoints = !a.noRemoval;
  a.bake.thinOversampled = !a.noThinning;
  a.bake.cullHidden = !a.keepHidden;
  std::optional<tbb::global_control> threadLimit;
  if (a.threads > 0) threadLimit.emplace(tbb::global_control::max_allowed_parallelism, a.threads);

  if (a.mpi)
    return runMpiBake(
        a.out, "impostors", a.json,
        [&](const MpiShard& shard) {
          const PvsDatabase pvs = PvsDatabase::open(a.db);
          const Scene scene = openScene(a.scene, limits_);
          std::optional<tbb::global_control> rankThreads;
          if (a.threads == 0)
            rankThreads.emplace(
                tbb::global_control::max_allowed_parallelism,
                std::max(1u, std::thread::hardware_concurrency() / shard.localRanks));
          const ImpostorBakeReport r = bakeShardOf(scene, pvs, fileCells, shard.rank, shard.size,
                                                   shard.out, /*progress=*/shard.rank == 0);
          return MpiShardCounts{r.cells, r.resumedCells};
        },
        [&](const std::vector<std::string>& shards) {
          mergeImpostorDatabases(std::vector<std::filesystem::path>(shards.begin(), shards.end()),
                                 a.out);
          return ImpostorDatabase::open(a.out).cellCount();
        });
  std::optional<PvsDatabase> pvsDb;
  if (!oneCell) pvsDb.emplace(PvsDatabase::open(a.db));
  const Scene scene = openScene(a.scene, limits_);
  if (!oneCell) return bakeDatabase(scene, *pvsDb, fileCells);
  warnIfOutsideScene(scene, fileCell, "--cell", a.cell);
  const Box3f cell = toLocal(scene, fileCell);
  const ImpostorWorld world(scene, {a.ground, LightingOptions{}, a.lightingCache});
  const CellImpostors r = world.bakeCell(cell, a.placement, a.bake);

  // What the sites left as geometry cost streamed as faces.
  const size_t leftBytes = world.geometryBytes(r.geometryFaces);
  size_t points = 0, bytes = 0, geometryBytes = 0;
  for (size_t i = 0; i < r.impostors.size(); ++i) {
    points += r.stats[i].points;
    bytes += r.stats[i].bytes;
    geometryBytes += r.geometryBytes[i];
  }
  if (a.json) {
    json impostors = json::array();
    for (size_t i = 0; i < r.impostors.size(); ++i) {
      const ImpostorSite& site = r.placement.sites[r.siteOf[i]];
      const ImpostorStats& s = r.stats[i];
      impostors.push_back({{"sector", site.sector},
                           {"band", site.band},
                           {"box", fileBoxJson(scene, site.box)},
                           {"triangles", site.triangles.size()},
                           {"faces_replaced", r.replacedFaces[i].size()},
                           {"geometry_bytes", r.geometryBytes[i]},
                           {"points", s.points},
                           {"screen_pixels", s.screenPixels},
                           {"points_per_pixel", s.pointsPerPixel},
                           {"covered_pixels", s.coveredPixels},
                           {"bytes", s.bytes},
                           {"bake_s", s.seconds},
                           {"stats", statsJson(s)}});
    }
    const json stats = {{"pvs_triangles", r.pvsTriangles},
                        {"far_triangles", r.placement.farTriangles},
                        {"near_triangles", r.placement.nearTriangles},
                        {"light_groups", r.placement.lightGroups},
                        {"impostors", r.impostors.size()},
                        {"refused", r.refused},
                        {"geometry_faces", r.geometryFaces.size()},
                        {"geometry_faces_bytes", leftBytes},
                        {"points", points},
                        {"bytes", bytes},
                        {"geometry_bytes", geometryBytes},
                        {"pvs_s", r.pvsSeconds},
                        {"bake_s", r.seconds},
                        {"why", r.placement.why}};
    std::cout << json{{"cell", fileBoxJson(scene, cell)},
                      {"impostors", impostors},
                      {"stats", stats}}
                     .dump()
              << "\n";
    return 0;
  }
  fmt::print("impostors of cell {} in {}: {}\n", a.cell, scene.name, r.placement.why);
  fmt::print("  PVS {} triangles ({:.2f} s): {} within d = {} m, {} beyond\n", r.pvsTriangles,
             r.pvsSeconds, r.placement.nearTriangles, a.placement.nearDistance,
             r.placement.farTriangles);
  for (const std::string& why : r.refused) fmt::print("  refused: {}\n", why);
  if (!r.geometryFaces.empty())
    fmt::print("  left as geometry: {} faces, {} bytes as a Geometry message\n",
               r.geometryFaces.size(), leftBytes);
  if (r.impostors.empty()) return 0;
  fmt::print("\n  {:>6} {:>4} {:>9} {:>9} {:>9} {:>8} {:>9} {:>10} {:>10} {:>7}\n", "sector",
             "band", "triangles", "points", "screen px", "pts/px", "covered", "bytes", "geometry B",
             "bake s");
  for (size_t i = 0; i < r.impostors.size(); ++i) {
    const ImpostorSite& site = r.placement.sites[r.siteOf[i]];
    const ImpostorStats& s = r.stats[i];
    fmt::print("  {:>6} {:>4} {:>9} {:>9} {:>9} {:>8.2f} {:>9} {:>10} {:>10} {:>7.1f}\n",
               site.sector, site.band, site.triangles.size(), s.points, s.screenPixels,
               s.pointsPerPixel, s.coveredPixels, s.bytes, r.geometryBytes[i], s.seconds);
  }
  fmt::print("  {:>6} {:>4} {:>9} {:>9} {:>9} {:>8} {:>9} {:>10} {:>10} {:>7.1f}\n", "total", "",
             "", points, "", "", "", bytes, geometryBytes, r.seconds);
  return 0;
}

}  // namespace vistream
