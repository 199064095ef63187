#include "server/cmd/pvs_commands.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "common/cmd/cli.h"
#include "common/core/error.h"
#include "common/core/parse.h"
#include "common/core/progress.h"
#include "common/core/stats_output.h"
#include "common/core/timer.h"
#include "common/generate/path.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/world/free_space.h"
#include "common/world/static_world.h"
#include "server/cmd/impostor_bench.h"
#include "server/cmd/impostor_commands.h"
#include "server/cmd/mpi_bake.h"
#include "server/cmd/pvs_bench.h"
#include "server/cmd/pvs_truth.h"
#include "server/cmd/scene_boxes.h"
#include "server/cmd/walk_bench.h"
#include "server/impostor/impostor_database.h"
#include "server/stream/stream_world.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/fused_pvs.h"
#include "server/visibility/hierarchical_culling.h"
#include "server/visibility/horizon_fusion.h"
#include "server/visibility/pvs_bake.h"
#include "server/visibility/pvs_database.h"

namespace vistream {
namespace {

using nlohmann::json;

int cmdCell(const std::string& spec, const SceneLimits& limits, const std::string& cellText,
            const std::string& method, const PvsOptions& options,
            const FusedPvsOptions& fusedOptions, const std::optional<TruthOptions>& truth,
            bool asJson) {
  // --epsilon and --fused-res are range-checked at parse time.
  if (method != "auto" && method != "paper" && method != "fused" && method != "horizons")
    throwInputError("--method: expected 'auto', 'paper', 'fused' or 'horizons', got '{}'", method);
  const Box3d fileCell = parseFileBox(cellText, "--cell");
  const PvsWorld world =
      makePvsWorld(openScene(spec, limits), truth.has_value(), StaticWorldParts::Solids);
  const Scene& scene = world.scene;
  warnIfOutsideScene(scene, fileCell, "--cell", cellText);
  const Box3f cell = toLocal(scene, fileCell);
  EpsilonPvs& pvs = *world.pvs;
  const std::unique_ptr<HorizonFusion> horizons =
      makeHorizonFusion(scene,
                        method == "auto"       ? FusionChoice::Auto
                        : method == "horizons" ? FusionChoice::Horizons
                                               : FusionChoice::None,
                        &world.statics);  // its triangles, rays and solids: built once
  pvs.setFusion(horizons.get());
  const std::string used = method == "auto" ? (horizons ? "horizons" : "paper") : method;
  FusedPvsStats fusedStats;
  const PvsResult r = method == "fused"
                          ? FusedPvs(pvs, fusedOptions).compute(cell, options, &fusedStats)
                          : pvs.compute(cell, options);
  std::optional<PvsTruth> compared;
  if (truth) compared = comparePvsWithTruth(world, cell, r.faces, *truth);
  if (asJson) {
    json objects = json::array();
    for (uint32_t o : r.objects) objects.push_back(scene.objects[o].name);
    json stats = statsJson(r.stats);
    stats["method"] = used;
    if (method == "fused") {
      json fused = statsJson(fusedStats);
      fused["epsilon"] = fusedOptions.epsilon;
      fused["resolution"] = fusedOptions.resolution;
      stats["fused"] = fused;
    }
    json out{{"faces", r.faces}, {"objects", objects}, {"stats", stats}};
    if (compared) out["ground_truth"] = compared->toJson();
    std::cout << out.dump() << "\n";
    return compared && !compared->missing.empty() ? 3 : 0;
  }
  const PvsStats& s = r.stats;
  fmt::print("PVS of cell {} ({}): {} of {} faces ({:.1f}% culled), {} objects\n", cellText, used,
             r.faces.size(), scene.faceCount,
             100.0 * double(s.facesOccluded) / double(std::max<size_t>(1, s.faces)),
             r.objects.size());
  fmt::print("{}", statsTable(s));
  if (method == "fused")
    fmt::print("  fused occluders (eps {} m, {} pixels per cube side):\n{}", fusedOptions.epsilon,
               fusedOptions.resolution, statsTable(fusedStats, "    "));
  if (!compared) return 0;
  const PvsTruth& c = *compared;
  fmt::print("sampled ground truth ({} viewpoints, {} inside solids left out, {} rays):\n",
             c.truth.viewpoints, c.truth.insideSolid, c.truth.rays);
  fmt::print("  {:<34} {:>10}\n", "faces seen", c.truth.faces.size());
  fmt::print("  {:<34} {:>10}\n", "of them found by probes only", c.truth.probeOnly);
  fmt::print("  {:<34} {:>10.2f}\n", "PVS / seen", c.pvsOverSeen());
  fmt::print("  {:<34} {:>10}\n", "missing (seen, not in the PVS)", c.missing.size());
  fmt::print("  {:<34} {:>10}\n", "unseen PVS faces", c.unseen());
  for (size_t b = 0; b < c.unseenByDistance.size(); ++b) {
    const auto [from, to] = PvsTruth::band(b);
    const std::string band = std::isinf(to) ? fmt::format("beyond {:.0f} m", from)
                                            : fmt::format("{:.0f}-{:.0f} m", from, to);
    fmt::print("    {:<32} {:>10}\n", band, c.unseenByDistance[b]);
  }
  fmt::print("    {:<32} {:>10}\n", "facing up", c.unseenUp);
  fmt::print("    {:<32} {:>10}\n", "facing sideways", c.unseenSide);
  fmt::print("    {:<32} {:>10}\n", "facing down", c.unseenDown);
  if (!c.missing.empty()) {
    spdlog::error("the PVS misses {} faces seen from the cell (first: {})", c.missing.size(),
                  c.missing.front());
    return 3;
  }
  return 0;
}

int cmdBake(const std::string& spec, const SceneLimits& limits, const GroundChoice& ground,
            const std::string& cellSizeText, const std::string& regionText, unsigned threads,
            const std::string& shardText, bool coarseToFine, const PvsOptions& pvsOptions,
            const std::string& fusion, const std::string& out, bool asJson, bool mpi) {
  BakeOptions options;
  options.pvs = pvsOptions;
  options.threads = threads;
  options.coarseToFine = coarseToFine;
  {
    const size_t commas = size_t(std::count(cellSizeText.begin(), cellSizeText.end(), ','));
    const auto v = parseNumberList(cellSizeText, commas == 0 ? 1 : 3, "--cell-size");
    options.cellSize =
        commas == 0 ? glm::vec3(float(v[0])) : glm::vec3(float(v[0]), float(v[1]), float(v[2]));
    if (!(options.cellSize.x > 0 && options.cellSize.y > 0 && options.cellSize.z > 0))
      throwInputError("--cell-size: every component must be positive, got '{}'", cellSizeText);
  }
  if (!shardText.empty()) std::tie(options.shardIndex, options.shardCount) = parseShard(shardText);
  if (mpi && !shardText.empty())
    throwInputError("--mpi gives each rank its shard (rank i of n bakes shard i/n): drop --shard");
  std::optional<Box3d> fileRegion;
  if (!regionText.empty()) fileRegion = parseFileBox(regionText, "--region");
  // Loads the scene and bakes `o` into `path` (every rank of an MPI job does).
  auto bakeInto = [&](BakeOptions o, const std::string& path, bool progress) {
    const Scene scene = openScene(spec, limits);
    if (fileRegion) {
      warnIfOutsideScene(scene, *fileRegion, "--region", regionText);
      o.region = toLocal(scene, *fileRegion);
    }
    StaticWorldOptions worldOptions;
    worldOptions.ground = ground;
    const StaticWorld world = buildStaticWorld(scene, worldOptions);
    EpsilonPvs pvs(scene, OccluderOptions{}, &world);
    const std::unique_ptr<HorizonFusion> horizons =
        makeHorizonFusion(scene, *parseFusionChoice(fusion), &world);
    pvs.setFusion(horizons.get());
    std::unique_ptr<ProgressBar> bar;
    std::mutex barMutex;  // guards creation of the bar from the first progress call
    if (progress)
      o.progress = [&](size_t done, size_t total) {
        std::lock_guard lock(barMutex);
        if (!bar) {
          bar = std::make_unique<ProgressBar>("baking cells", total);
          bar->advance(done);
        } else {
          bar->advance(1);
        }
      };
    BakeReport r = bakePvs(scene, pvs, world.freeSpace, o, path);
    if (bar) bar->finish();
    return std::pair{scene.name, r};
  };
  if (mpi) {
    const int status = runMpiBake(
        out, "the PVS", asJson,
        [&](const MpiShard& shard) {
          BakeOptions o = options;
          o.shardIndex = shard.rank;
          o.shardCount = shard.size;
          if (threads == 0)
            o.threads = std::max(1u, std::thread::hardware_concurrency() / shard.localRanks);
          const BakeReport r = bakeInto(o, shard.out, shard.rank == 0).second;
          return MpiShardCounts{r.shardCells, r.resumedCells};
        },
        [&](const std::vector<std::string>& shards) {
          mergePvsDatabases(std::vector<std::filesystem::path>(shards.begin(), shards.end()), out);
          return PvsDatabase::open(out).cellCount();
        });
    return status;
  }
  const auto [sceneName, r] = bakeInto(options, out, true);
  if (asJson) {
    std::cout << json{{"out", out},
                      {"grid_cells", r.gridCells},
                      {"free_space_cells", r.freeCells},
                      {"shard_cells", r.shardCells},
                      {"resumed_cells", r.resumedCells},
                      {"computed_cells", r.computedCells},
                      {"time_ms", r.timeMs},
                      {"mean_cell_ms", r.meanCellMs},
                      {"mean_pvs_faces",
                       r.shardCells ? double(r.totalFaces) / double(r.shardCells) : 0.0}}
                     .dump(2)
              << "\n";
  } else {
    fmt::print("baked {} -> {}\n", sceneName, out);
    fmt::print("  {:<28} {:>12}\n", "grid cells", r.gridCells);
    fmt::print("  {:<28} {:>12}\n", "cells over free space", r.freeCells);
    fmt::print("  {:<28} {:>12}\n", "cells in this shard", r.shardCells);
    fmt::print("  {:<28} {:>12}\n", "resumed from journal", r.resumedCells);
    fmt::print("  {:<28} {:>12}\n", "computed", r.computedCells);
    fmt::print("  {:<28} {:>12.1f}\n", "time (s)", r.timeMs / 1000.0);
    fmt::print("  {:<28} {:>12.2f}\n", "mean time per cell (ms)", r.meanCellMs);
    fmt::print("  {:<28} {:>12.1f}\n", "mean PVS size (faces)",
               r.shardCells ? double(r.totalFaces) / double(r.shardCells) : 0.0);
  }
  return 0;
}

int cmdQuery(const std::string& dbPath, const std::string& pointText, const std::string& cellText,
             bool asJson, bool withFaces) {
  if (pointText.empty() == cellText.empty())
    throwInputError("give exactly one of --point x,y,z or --cell i,j,k");
  const PvsDatabase db = PvsDatabase::open(dbPath);
  const ViewCellGrid grid = db.header().grid();
  glm::ivec3 ijk;
  if (!pointText.empty()) {
    const auto p = parseNumberList(pointText, 3, "--point");
    const glm::vec3 local(glm::dvec3(p[0], p[1], p[2]) - db.header().origin);
    const auto c = grid.cellOf(local);
    if (!c) throwInputError("--point {} lies outside the database's grid", pointText);
    ijk = *c;
  } else {
    const auto v = parseNumberList(cellText, 3, "--cell");
    for (int a = 0; a < 3; ++a) {
      if (v[size_t(a)] != std::floor(v[size_t(a)]))
        throwInputError("--cell: '{}' must be three integers", cellText);
      ijk[a] = int(v[size_t(a)]);
    }
    if (!grid.contains(ijk))
      throwInputError("--cell {} is outside the grid ({} x {} x {} cells)", cellText, grid.dims().x,
                      grid.dims().y, grid.dims().z);
  }
  const uint32_t index = uint32_t(grid.linearIndex(ijk));
  const auto faces = db.cell(index);
  if (!faces)
    throwInputError(
        "cell {},{},{} is not in {} (outside the free space, or baked by another shard)", ijk.x,
        ijk.y, ijk.z, dbPath);
  const Box3f box = grid.cellBox(ijk);
  const glm::dvec3 lo = db.header().origin + glm::dvec3(box.lo),
                   hi = db.header().origin + glm::dvec3(box.hi);
  if (asJson) {
    std::cout << json{{"cell", {ijk.x, ijk.y, ijk.z}},
                      {"box", {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z}},
                      {"faces", *faces},
                      {"scene", db.header().sceneName},
                      {"method", db.header().method}}
                     .dump()
              << "\n";
  } else {
    // A PVS holds thousands of face IDs: a summary by default, the IDs on request.
    fmt::print("cell {},{},{} [{:.3f},{:.3f},{:.3f} .. {:.3f},{:.3f},{:.3f}]: {} faces\n", ijk.x,
               ijk.y, ijk.z, lo.x, lo.y, lo.z, hi.x, hi.y, hi.z, faces->size());
    fmt::print("  {:<28} {}\n", "scene", db.header().sceneName);
    fmt::print("  {:<28} {}\n", "method", db.header().method);
    if (!faces->empty())
      fmt::print("  {:<28} {} .. {}\n", "face IDs", *std::min_element(faces->begin(), faces->end()),
                 *std::max_element(faces->begin(), faces->end()));
    if (withFaces)
      fmt::print("{}\n", fmt::join(*faces, " "));
    else
      fmt::print("(--faces lists the face IDs, --json prints them with the rest)\n");
  }
  return 0;
}

int cmdWalk(const std::string& spec, const SceneLimits& limits, const std::string& pathFile,
            const std::string& method, const CullingOptions& base, bool asJson, bool withFaces) {
  CullingOptions options = base;
  options.method = parseCullingMethod(method);
  options.collectFaces = withFaces;
  // --p-skip, --p-vp, --fov and --occluders are range-checked at parse time.
  const auto path = readPath(pathFile);
  const Scene scene = openScene(spec, limits);
  const CullingScene culling(scene);
  CullingViewer viewer(culling, options);
  json frames = json::array();
  double tests = 0, cullMs = 0, frameMs = 0, faces = 0, propagated = 0, skipped = 0;
  for (size_t i = 0; i < path.size(); ++i) {
    const PathSample& s = path[i];
    const FrameResult r = viewer.frame(glm::dvec3(scene.toLocal(s.position)), s.yawDeg, s.pitchDeg);
    const double fms = r.cullingMs + double(r.visibleFaces) * culling.drawMsPerFace();
    tests += double(r.nodeTests);
    propagated += double(r.propagated);
    skipped += double(r.skipped);
    cullMs += r.cullingMs;
    frameMs += fms;
    faces += double(r.visibleFaces);
    json f = {{"frame", i},
              {"node_tests", r.nodeTests},
              {"propagated", r.propagated},
              {"propagation_tries", r.propagationTries},
              {"skipped", r.skipped},
              {"culling_ms", r.cullingMs},
              {"frame_ms", fms},
              {"visible_leaves", r.visibleLeaves},
              {"visible_faces", r.visibleFaces}};
    if (withFaces) f["faces"] = r.faces;
    frames.push_back(std::move(f));
    if (!asJson)
      fmt::print(
          "frame {:>5}  node tests {:>6}  propagated {:>4}  skipped {:>4}  culling {:>8.3f} ms  "
          "frame {:>8.3f} ms  "
          "leaves {:>5}  faces {:>7}\n",
          i, r.nodeTests, r.propagated, r.skipped, r.cullingMs, fms, r.visibleLeaves,
          r.visibleFaces);
  }
  const double n = double(std::max<size_t>(1, path.size()));
  const json summary = {{"method", method},
                        {"frames", path.size()},
                        {"kd_nodes", culling.tree().nodes().size()},
                        {"occluders", options.occluders},
                        {"node_tests_mean", tests / n},
                        {"propagated_mean", propagated / n},
                        {"skipped_mean", skipped / n},
                        {"culling_ms_mean", cullMs / n},
                        {"frame_ms_mean", frameMs / n},
                        {"visible_faces_mean", faces / n},
                        {"draw_ms_per_face", culling.drawMsPerFace()},
                        {"cost_model", "frame_ms = culling_ms + visible_faces * draw_ms_per_face"}};
  if (asJson) {
    std::cout << json{{"summary", summary}, {"frames", frames}}.dump() << "\n";
  } else {
    fmt::print("method {}: {} frames, {} kD-tree nodes, {} occluders per view\n", method,
               path.size(), culling.tree().nodes().size(), options.occluders);
    fmt::print(
        "  mean node tests {:.1f}, propagated {:.1f}, skipped {:.1f}, culling {:.3f} ms, frame "
        "{:.3f} ms, "
        "visible faces {:.0f}\n",
        tests / n, propagated / n, skipped / n, cullMs / n, frameMs / n, faces / n);
    fmt::print(
        "  cost model: frame = culling + visible faces x {:.2e} ms (mean cost of a face in a "
        "software z-buffer rasterizer at 640x480)\n",
        culling.drawMsPerFace());
  }
  return 0;
}

// Adds --scenes to `sub`: SCENEs as one comma-separated word, split into
// `scenes` when given; help shows the list `scenes` holds now.
void addScenesOption(CLI::App* sub, std::vector<std::string>& scenes) {
  sub->add_option_function<std::string>(
         "--scenes", [&scenes](const std::string& text) { scenes = splitCommaList(text); },
         "comma-separated SCENEs")
      ->default_str(fmt::format("{}", fmt::join(scenes, ",")));
}

}  // namespace

int runPvsTool(int argc, char** argv) {
  CLI::App app{
      "vistream-pvs: conservative potentially visible sets of view cells "
      "(Cohen-Or and Zadicario 1998).\n" +
      sceneSpecHelp()};
  std::string logLevel;
  setUpToolApp(app, logLevel);

  // Every subcommand that loads a scene file takes the triangle limit.
  SceneLimits limits;
  auto addSceneLimits = [&](CLI::App* sub) { addSceneLimitsOption(*sub, limits); };
  GroundChoice ground;

  auto* cell = app.add_subcommand("cell", "the PVS of one view cell");
  std::string scene, cellText, method = "auto", fusion = "auto";
  bool asJson = false, noBbox = false, noIncremental = false, noRedundantOccluders = false,
       noRedundantRays = false, noBackFaces = false, noPlanarFusion = false, keepFaceless = false;
  size_t largeOccluders = 0;
  // The PVS stages every subcommand that computes a PVS can switch off.
  auto addPvsStageFlags = [&](CLI::App* sub) {
    sub->add_flag("--no-bbox", noBbox, "skip the bounding-box stage");
    sub->add_flag("--no-incremental", noIncremental, "every line traverses the space on its own");
    sub->add_flag("--no-redundant-occluders", noRedundantOccluders,
                  "keep occluded objects as occluders");
    sub->add_flag("--no-redundant-rays", noRedundantRays, "cast every corner-vertex line");
    sub->add_flag("--no-back-faces", noBackFaces,
                  "keep faces that face away from the whole cell with a solid behind them");
    sub->add_flag(
        "--keep-faces-without-area", keepFaceless,
        "keep faces whose every triangle is degenerate (they have no area to be seen by)");
    sub->add_flag("--no-planar-fusion", noPlanarFusion,
                  "keep faces that only solids fused within one plane hide (a wall of several "
                  "pieces)");
  };
  cell->add_option("--scene", scene, "SCENE")->required();
  cell->add_option("--cell", cellText, "x0,y0,z0,x1,y1,z1 in file coordinates")->required();
  cell->add_option("--method", method,
                   "paper (single convex occluders), horizons (then fused occlusion horizons over "
                   "solid columns), auto (horizons where the scene has solid columns, else paper) "
                   "or fused (then cube-map fusion)")
      ->check(CLI::IsMember({"auto", "paper", "horizons", "fused"}));
  addPvsStageFlags(cell);
  cell->add_option("--large-occluders", largeOccluders,
                   "use only the K largest occluders by solid angle (0: all)")
      ->check(atLeast<size_t>(0));
  cell->add_flag("--json", asJson,
                 "one JSON object on stdout: faces, objects, stats (and ground_truth)");
  bool groundTruth = false;
  TruthOptions truthOptions;
  cell->add_flag("--ground-truth", groundTruth,
                 "also sample what is seen from the cell: PVS / seen, missing faces (exit 3 if "
                 "any), the unseen PVS faces by distance and facing");
  cell->add_option("--gt-points", truthOptions.points, "ground-truth viewpoints")
      ->check(atLeast<size_t>(1));
  cell->add_option("--gt-res", truthOptions.resolution, "ground-truth rays per cube face side")
      ->check(inRange(1, 4096));
  cell->add_option("--gt-probes", truthOptions.probes,
                   "ground-truth rays aimed at each triangle of a PVS face from each viewpoint (0: "
                   "the cube maps only)")
      ->check(inRange(0, 256));
  FusedPvsOptions fusedOptions;
  cell->add_option("--epsilon", fusedOptions.epsilon,
                   "fused: occluder erosion and sample spacing bound (m)")
      ->check(positive());
  cell->add_option("--fused-res", fusedOptions.resolution,
                   "fused: occlusion cube-map pixels per side")
      ->check(inRange(4, 2048));
  addSceneLimits(cell);

  auto* bake =
      app.add_subcommand("bake", "bake the PVS of every cell over the free space into a database");
  std::string cellSize, region, shard, out;
  unsigned threads = 0;
  bool noCoarse = false, bakeMpi = false;
  bake->add_option("--scene", scene, "SCENE")->required();
  bake->add_option("--cell-size", cellSize, "X or X,Y,Z in metres")->required();
  bake->add_option("--region", region, "x0,y0,z0,x1,y1,z1: bake only this box (file coordinates)");
  bake->add_option("--threads", threads, "worker threads (0: all cores)")
      ->check(atLeast<unsigned>(0));
  bake->add_option("--shard", shard, "i/n: bake only shard i of n (merge shards with 'merge')");
  bake->add_option("--out,-o", out, "output database")->required();
  bake->add_flag("--no-coarse-to-fine", noCoarse, "bake every cell from scratch");
  bake->add_flag("--mpi", bakeMpi,
                 "run as one rank of an MPI job (mpirun -n N vistream-pvs bake --mpi ...): rank i "
                 "of n bakes shard i/n, rank 0 merges them into --out");
  bake->add_option("--fusion", fusion,
                   "occlusion horizons after the single occluders: auto (where the scene has "
                   "solid columns), horizons or none")
      ->check(CLI::IsMember({"auto", "horizons", "none"}));
  addPvsStageFlags(bake);
  bake->add_flag("--json", asJson, "statistics as JSON");
  addSceneLimits(bake);
  addGroundOption(*bake, ground);

  auto* query =
      app.add_subcommand("query", "the PVS of the cell holding a point, from a baked database");
  std::string db, point, cellIndex;
  bool queryFaces = false;
  query->add_option("--db", db, "baked database")->required();
  query->add_option("--point", point, "x,y,z in file coordinates");
  query->add_option("--cell", cellIndex, "i,j,k grid cell");
  query->add_flag("--faces", queryFaces, "list every face ID of the PVS, not only a summary");
  query->add_flag("--json", asJson, "one JSON object on stdout, face IDs included");

  auto* merge = app.add_subcommand("merge", "merge shard databases of one scene and grid");
  std::vector<std::string> inputs;
  merge->add_option("inputs", inputs, "shard databases")->required();
  merge->add_option("--out,-o", out, "merged database")->required();
  auto* impostorMerge = app.add_subcommand(
      "impostor-merge", "merge shard impostor databases baked from one PVS database");
  impostorMerge->add_option("inputs", inputs, "shard impostor databases")->required();
  impostorMerge->add_option("--out,-o", out, "merged impostor database")->required();

  auto* bench =
      app.add_subcommand("bench",
                         "Tables 1 and 2 of the paper; per method, PVS accuracy against time "
                         "and the bake time of a district");
  PvsBenchOptions benchOptions;
  addScenesOption(bench, benchOptions.scenes);
  bench->add_option("--cells", benchOptions.cells, "street cells per city for Tables 1 and 2")
      ->check(atLeast<size_t>(1));
  bench
      ->add_option("--accuracy-cells", benchOptions.accuracyCells,
                   "cells per scene and cell size for the accuracy table")
      ->check(atLeast<size_t>(1));
  bench->add_option("--gt-res", benchOptions.groundTruthRes, "ground-truth rays per cube face side")
      ->check(inRange(1, 4096));
  bench
      ->add_option("--gt-points", benchOptions.groundTruthPoints,
                   "ground-truth viewpoints per cell")
      ->check(atLeast<size_t>(1));
  bench
      ->add_option("--gt-probes", benchOptions.groundTruthProbes,
                   "ground-truth rays aimed at each triangle of a PVS face from each viewpoint "
                   "(0: the cube maps only)")
      ->check(inRange(0, 256));
  bench->add_option("--seed", benchOptions.seed, "seed for cell placement")
      ->check(atLeast<uint64_t>(0));
  bench
      ->add_option("--district", benchOptions.districtSize,
                   "side of the square district baked per scene and method, around the scene's "
                   "centre (metres; 0: no bake)")
      ->check(nonNegative());
  bench
      ->add_option("--bake-cell", benchOptions.bakeCellSize,
                   "view cell size of the district bake (metres)")
      ->check(positive())
      ->default_str(fmt::format("the server's, {}", StreamWorldOptions{}.cellSize));
  bench
      ->add_option("--bake-threads", benchOptions.bakeThreads,
                   "worker threads of the district bake (0: all cores)")
      ->check(atLeast<unsigned>(0));
  bench->add_option("--plot", benchOptions.plotDir, "directory for accuracy.dat/.png (gnuplot)");
  bench->add_flag("--json", benchOptions.json, "one JSON object on stdout");

  auto* walk = app.add_subcommand(
      "walk", "replay a path with hierarchical visibility culling (Bittner and Havran 2001)");
  std::string pathFile, walkMethod = "A";
  CullingOptions cullOptions;
  bool withFaces = false;
  walk->add_option("--scene", scene, "SCENE")->required();
  walk->add_option("--path", pathFile, "path CSV (t,x,y,z,yaw_deg,pitch_deg)")->required();
  walk->add_option("--method", walkMethod,
                   "A (classical), B (hierarchy updating), C (B + visibility propagation), "
                   "D (C + conservative updating), adaptive (D with learnt probabilities)");
  walk->add_option("--occluders", cullOptions.occluders, "occluders per viewpoint")
      ->check(atLeast<size_t>(1));
  walk->add_option("--p-skip", cullOptions.pSkip,
                   "method D: probability of skipping a visible node's test")
      ->check(inRange(0.0, 1.0));
  walk->add_option("--p-vp", cullOptions.pVp,
                   "methods C and D: probability of trying visibility propagation")
      ->check(inRange(0.0, 1.0));
  walk->add_option("--seed", cullOptions.seed, "random seed for D")->check(atLeast<uint64_t>(0));
  walk->add_option("--fov", cullOptions.fovDeg, "horizontal field of view in degrees (4:3 frustum)")
      ->check(between(0.0, 180.0));
  walk->add_flag("--json", asJson, "one JSON object: summary and frames");
  walk->add_flag("--with-faces", withFaces, "list the faces of visible leaves per frame");
  addSceneLimits(walk);

  auto* walkBench = app.add_subcommand(
      "walk-bench", "Figures 8-11 of Bittner and Havran 2001: methods against speed and p_skip");
  WalkBenchOptions walkBenchOptions;
  addScenesOption(walkBench, walkBenchOptions.scenes);
  walkBench->add_option("--frames", walkBenchOptions.frames, "frames per path")
      ->check(atLeast<size_t>(1));
  walkBench
      ->add_option("--occluders", walkBenchOptions.occluders,
                   "occluders per viewpoint (0: the paper's, 32 for interior2, else 16)")
      ->check(atLeast<size_t>(0));
  walkBench
      ->add_option("--repeats", walkBenchOptions.repeats,
                   "runs per configuration; times are medians")
      ->check(atLeast<size_t>(1));
  walkBench->add_option("--plot-dir", walkBenchOptions.plotDir,
                        "write .dat files and a PNG of Figures 8-11 per scene here");
  walkBench->add_flag("--json", walkBenchOptions.json, "one JSON array on stdout");

  ImpostorCommand impostors(app, limits);

  auto* impostorBench = app.add_subcommand(
      "impostor-bench",
      "Table 5.1 of Wimmer 2001 (points, points per screen pixel, bake time, memory) for three "
      "impostors of a street cell per scene, and a sweep of the bake's accuracy knobs");
  ImpostorBenchOptions impostorBenchOptions = defaultImpostorBenchOptions();
  addScenesOption(impostorBench, impostorBenchOptions.scenes);
  impostorBench
      ->add_option("--cell", impostorBenchOptions.cell,
                   "x0,y0,z0,x1,y1,z1: the view cell in every scene (file coordinates)")
      ->capture_default_str();
  impostorBench
      ->add_option("--repeats", impostorBenchOptions.repeats,
                   "bakes per configuration; times are medians")
      ->capture_default_str()
      ->check(atLeast<size_t>(1));
  impostorBench
      ->add_option("--near-distance", impostorBenchOptions.placement.nearDistance,
                   "d: impostors hold the PVS beyond it (metres)")
      ->capture_default_str()
      ->check(positive());
  impostorBench
      ->add_option("--min-triangles", impostorBenchOptions.placement.minTriangles,
                   "a lighter sector and band stays geometry")
      ->capture_default_str()
      ->check(atLeast<size_t>(1));
  std::string benchScreen = "640x480";
  impostorBench->add_option("--screen", benchScreen, "the viewer's screen, WIDTHxHEIGHT")
      ->capture_default_str();
  impostorBench
      ->add_option("--fov", impostorBenchOptions.screen.vfovDeg,
                   "the viewer's vertical field of view (degrees); the thesis's Table 5.1: 45")
      ->capture_default_str()
      ->check(between(1.0, 170.0));
  addLightingCacheOption(*impostorBench, impostorBenchOptions.lightingCache);
  impostorBench->add_flag(
      "--no-sweep", [&](int64_t) { impostorBenchOptions.sweep = false; }, "only Table 5.1");
  impostorBench->add_flag("--json", impostorBenchOptions.json, "one JSON array on stdout");

  // The acceleration switches shared by cell and bake.
  auto pvsOptionsFromFlags = [&] {
    PvsOptions options;
    options.boxStage = !noBbox;
    options.incremental = !noIncremental;
    options.dropOccludedOccluders = !noRedundantOccluders;
    options.removeRedundantLines = !noRedundantRays;
    options.backFaces = !noBackFaces;
    options.faceless = !keepFaceless;
    options.planarFusion = !noPlanarFusion;
    return options;
  };
  return runToolApp("vistream-pvs", app, argc, argv, logLevel, [&]() -> int {
    if (*cell) {
      PvsOptions options = pvsOptionsFromFlags();
      options.largeOccluders = largeOccluders;
      return cmdCell(scene, limits, cellText, method, options, fusedOptions,
                     groundTruth ? std::optional<TruthOptions>(truthOptions) : std::nullopt,
                     asJson);
    }
    if (*bake) {
      const PvsOptions options = pvsOptionsFromFlags();
      return cmdBake(scene, limits, ground, cellSize, region, threads, shard, !noCoarse, options,
                     fusion, out, asJson, bakeMpi);
    }
    if (*query) return cmdQuery(db, point, cellIndex, asJson, queryFaces);
    if (*walk) return cmdWalk(scene, limits, pathFile, walkMethod, cullOptions, asJson, withFaces);
    if (*walkBench) return runWalkBench(walkBenchOptions);
    if (*bench) return runPvsBench(benchOptions);
    if (impostors.chosen()) return impostors.run();
    if (*impostorBench) {
      const WidthHeight screen = parseWidthHeight(benchScreen, "--screen", 16, 8192);
      impostorBenchOptions.screen.width = screen.width;
      impostorBenchOptions.screen.height = screen.height;
      return runImpostorBench(impostorBenchOptions);
    }
    if (*merge) {
      std::vector<std::filesystem::path> paths(inputs.begin(), inputs.end());
      mergePvsDatabases(paths, out);
      fmt::print("merged {} databases into {}\n", paths.size(), out);
      return 0;
    }
    if (*impostorMerge) {
      std::vector<std::filesystem::path> paths(inputs.begin(), inputs.end());
      mergeImpostorDatabases(paths, out);
      fmt::print("merged {} impostor databases into {}\n", paths.size(), out);
      return 0;
    }
    return 2;
  });
}

}  // namespace vistream
