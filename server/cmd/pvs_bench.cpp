// Reproduces Tables 1 and 2 of Cohen-Or and Zadicario 1998 on the generated
// cities and measures the accuracy/time trade-off of the PVS against the
// sampled ground truth, and the time a district's bake takes with each
// method. All configurations run side by side in one process on the same
// cells; times per cell are medians over cells.
#include "server/cmd/pvs_bench.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <random>
#include <system_error>

#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/core/timer.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "common/world/free_space.h"
#include "common/world/sealed_surface.h"
#include "common/world/static_world.h"
#include "server/cmd/pvs_truth.h"
#include "server/stream/stream_world.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/horizon_fusion.h"
#include "server/visibility/pvs_bake.h"

namespace vistream {
namespace {

using nlohmann::json;

double mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

// Cells of the given horizontal size centred on random free-space columns,
// from 0.2 m above the floor up to eye height or the cell size.
std::vector<Box3f> streetCells(const PvsWorld& w, float size, size_t count, uint64_t seed) {
  const auto columns = w.statics.freeSpace.walkableColumns();
  std::vector<Box3f> cells;
  if (columns.empty()) return cells;
  std::mt19937_64 rng(seed);
  const float height = std::min(size, 1.8f);
  for (size_t i = 0; i < count; ++i) {
    const auto c = columns[rng() % columns.size()];
    const glm::vec2 xz = w.statics.freeSpace.columnCentre(c.x, c.y);
    const float y = w.statics.freeSpace.floorHeight(c.x, c.y) + 0.2f;
    cells.emplace_back(glm::vec3(xz.x - size / 2, y, xz.y - size / 2),
                       glm::vec3(xz.x + size / 2, y + height, xz.y + size / 2));
  }
  return cells;
}

// A scene's name in the plot: a file's stem, without blanks (the .dat file
// is split at blanks).
std::string plotLabel(const std::string& spec) {
  std::string label = std::filesystem::path(spec).stem().string();
  std::replace(label.begin(), label.end(), ' ', '_');
  return label.empty() ? spec : label;
}

struct Config {
  const char* name;
  PvsOptions options;
};

std::vector<Config> table2Configs() {
  PvsOptions naive;
  naive.boxStage = naive.incremental = naive.dropOccludedOccluders = naive.removeRedundantLines =
      false;
  naive.planarFusion = false;  // the paper's single occluders (its accelerations are timed)
  PvsOptions box = naive;
  box.boxStage = true;
  PvsOptions occl = box;
  occl.dropOccludedOccluders = true;
  PvsOptions rays = box;
  rays.removeRedundantLines = true;
  PvsOptions full;
  full.planarFusion = false;
  return {{"no optimization", naive},
          {"bounding box", box},
          {"redundant occluders", occl},
          {"redundant rays", rays},
          {"fully optimized", full}};
}

// Every method and combination the accuracy table and the district bake
// compare: the paper's single convex occluders, + back faces of solids (and
// faces without area: PvsOptions::faceless), + solids fused within a plane (planar_fusion.h), +
// fused occlusion horizons (when the PVS has them: not indoors; the default of `vistream-pvs cell`
// and the bake).
struct Method {
  const char* name;
  PvsOptions options;
};

std::vector<Method> benchMethods(bool horizons) {
  PvsOptions paper;
  paper.backFaces = false;
  paper.faceless = false;
  paper.fusion = false;
  paper.planarFusion = false;
  PvsOptions backFaces = paper;
  backFaces.backFaces = true;
  backFaces.faceless = true;  // faces without area go with the back faces
  PvsOptions planar = backFaces;
  planar.planarFusion = true;
  std::vector<Method> methods{
      {"paper", paper}, {"+back faces", backFaces}, {"+planar fusion", planar}};
  if (horizons) methods.push_back({"+horizons", PvsOptions{}});
  return methods;
}

// A scratch directory for the district bakes' databases, removed with
// everything in it when the bench ends.
class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "vistream-pvs-bench-XXXXXX").string();
    if (!::mkdtemp(pattern.data()))
      throw std::system_error(errno, std::generic_category(), "cannot create " + pattern);
    path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// The district a bench bakes: the bake's own region (the scene's bounds in X
// and Z, its floors' eye range in Y; bakeGrid) cut to a square of `side`
// metres around the centre of the scene's bounds.
Box3f districtRegion(const PvsWorld& w, const BakeOptions& bake, double side) {
  const ViewCellGrid whole = bakeGrid(w.scene, w.statics.freeSpace, bake);
  Box3f region(whole.origin(), whole.origin() + glm::vec3(whole.dims()) * whole.cellSize());
  const glm::vec3 centre = w.scene.bounds().center();
  const float half = float(side / 2.0);
  region.lo.x = std::max(region.lo.x, centre.x - half);
  region.hi.x = std::min(region.hi.x, centre.x + half);
  region.lo.z = std::max(region.lo.z, centre.z - half);
  region.hi.z = std::min(region.hi.z, centre.z + half);
  return region;
}

}  // namespace

int runPvsBench(const PvsBenchOptions& options) {
  const Stopwatch total;
  json out;
  const bool human = !options.json;
  std::vector<std::string> cities;
  for (const auto& s : options.scenes)
    if (s.rfind("city1", 0) == 0 || s.rfind("city2", 0) == 0) cities.push_back(s);

  // ---- Tables 1 and 2 ---------------------------------------------------------
  for (const std::string& spec : options.cells > 0 ? cities : std::vector<std::string>{}) {
    PvsWorld w = makePvsWorld(openScene(spec));
    const float cellSize = float(w.typicalBuilding / 4.0);
    const auto cells = streetCells(w, cellSize, options.cells, options.seed);
    const auto configs = table2Configs();
    std::vector<std::vector<PvsStats>> stats(configs.size());
    std::vector<size_t> mismatches(configs.size(), 0);
    ProgressBar bar(spec + " tables", cells.size() * configs.size());
    for (const Box3f& cell : cells) {
      std::vector<uint32_t> reference;
      for (size_t c = configs.size(); c-- > 0;) {  // fully optimized first: it is the reference
        const PvsResult r = w.pvs->compute(cell, configs[c].options);
        if (c == configs.size() - 1)
          reference = r.faces;
        else if (r.faces != reference)
          ++mismatches[c];
        stats[c].push_back(r.stats);
        bar.advance();
      }
    }
    bar.finish();
    const auto& full = stats.back();
    std::vector<double> occludedFaces, occludedBoxes, firstOcc;
    size_t buildings = 0;
    for (const Object& o : w.scene.objects) buildings += o.name.rfind("building", 0) == 0;
    for (const auto& s : full) {
      occludedFaces.push_back(double(s.facesOccluded));
      occludedBoxes.push_back(double(s.objectBoxesOccluded));
      firstOcc.push_back(double(s.objectBoxesOccludedByFirst));
    }
    json t1 = {{"scene", spec},
               {"cell_size_m", cellSize},
               {"cells", cells.size()},
               {"total_polygons", w.scene.faceCount},
               {"occluded_polygons", mean(occludedFaces)},
               {"total_boxes", full.empty() ? 0 : full[0].objectBoxes},
               {"buildings", buildings},
               {"occluded_boxes", mean(occludedBoxes)},
               {"first_occluders", mean(firstOcc)}};
    json t2 = json::array();
    for (size_t c = 0; c < configs.size(); ++c) {
      auto pick = [&](auto f) {
        std::vector<double> v;
        for (const auto& s : stats[c]) v.push_back(double(f(s)));
        return v;
      };
      t2.push_back(
          {{"config", configs[c].name},
           {"total_ms", median(pick([](const PvsStats& s) { return s.timeMs; }))},
           {"box_stage_ms", median(pick([](const PvsStats& s) { return s.boxStageMs; }))},
           {"face_stage_ms", median(pick([](const PvsStats& s) { return s.faceStageMs; }))},
           {"line_box_tests", mean(pick([](const PvsStats& s) { return s.lineBoxTests; }))},
           {"line_polygon_tests", mean(pick([](const PvsStats& s) { return s.linePolygonTests; }))},
           {"lines_cast", mean(pick([](const PvsStats& s) { return s.linesCast; }))},
           {"pvs_differs_from_fully_optimized", mismatches[c]}});
    }
    out["table1"].push_back(t1);
    out["table2"].push_back({{"scene", spec}, {"configs", t2}});
    if (human) {
      fmt::print(
          "\nTable 1 ({}, {} street cells of {:.1f} m, paper: city1 21280/20062/2128/1954/1427, "
          "city2 21280/18713/2128/1755/1225)\n",
          spec, cells.size(), cellSize);
      fmt::print("  {:<28} {:>10}\n", "total polygons", w.scene.faceCount);
      fmt::print("  {:<28} {:>10.0f}\n", "occluded polygons", mean(occludedFaces));
      fmt::print("  {:<28} {:>10}\n", "total bounding boxes",
                 full.empty() ? 0 : full[0].objectBoxes);
      fmt::print("  {:<28} {:>10.0f}\n", "occluded boxes", mean(occludedBoxes));
      fmt::print("  {:<28} {:>10.0f}\n", "first occluders", mean(firstOcc));
      fmt::print(
          "\nTable 2 ({}, medians over {} cells; paper, R4400: 30170 / 8900 / 8850 / 7040 / 7030 "
          "ms)\n",
          spec, cells.size());
      fmt::print("  {:<22}", "");
      for (const auto& c : configs) fmt::print(" {:>14}", c.name);
      fmt::print("\n");
      const char* rows[] = {"total_ms",
                            "box_stage_ms",
                            "face_stage_ms",
                            "line_box_tests",
                            "line_polygon_tests",
                            "lines_cast",
                            "pvs_differs_from_fully_optimized"};
      const char* labels[] = {"total time (ms)",    "box stage (ms)",     "polygon stage (ms)",
                              "line/box tests",     "line/polygon tests", "lines cast",
                              "PVS differs (cells)"};
      for (size_t r = 0; r < std::size(rows); ++r) {
        fmt::print("  {:<22}", labels[r]);
        for (const auto& c : t2) fmt::print(" {:>14.3f}", c[rows[r]].get<double>());
        fmt::print("\n");
      }
      fmt::print(
          "  speed-up fully optimized over no optimization: {:.1f}x (paper: 4.3x)\n",
          t2[0]["total_ms"].get<double>() / std::max(1e-9, t2.back()["total_ms"].get<double>()));
    }
  }

  // ---- accuracy against time: PVS over ground truth by cell size ------------
  std::vector<std::string> lines;
  // The district bakes write their databases here.
  std::optional<ScratchDir> scratch;
  if (options.districtSize > 0) scratch.emplace();
  const float bakeCell =
      options.bakeCellSize > 0 ? options.bakeCellSize : StreamWorldOptions{}.cellSize;
  size_t bakes = 0;
  for (const std::string& spec : options.scenes) {
    PvsWorld w = makePvsWorld(openScene(spec));
    const bool indoor = spec.rfind("interior", 0) == 0;
    // The fused occlusion horizons (horizon_fusion.h) run where
    // `vistream-pvs cell --method auto` runs them: where the scene has solid
    // columns (cities and terrain; not the interiors, whose walls are
    // thinner than a column and whose planar fusion leaves the horizons'
    // walls nothing to cull).
    auto horizon = std::make_unique<HorizonFusion>(w.scene, w.statics);
    if (horizon->solidColumns() == 0)
      horizon.reset();
    else
      w.pvs->setFusion(horizon.get());
    const std::vector<float> sizes = indoor ? std::vector<float>{0.5f, 1.0f, 2.0f, 4.0f}
                                            : std::vector<float>{2.0f, 4.0f, 8.0f, 16.0f};
    if (human)
      fmt::print(
          "\nAccuracy against time ({}, {} cells per size, the same cells for every method; ground "
          "truth {} points x {}^2 rays per cube face + {} probe rays per triangle of every "
          "method's PVS faces)\n"
          "  {:>8} {:<20} {:>10} {:>10} {:>14} {:>12} {:>10} {:>8}\n",
          spec, options.accuracyCells, options.groundTruthPoints, options.groundTruthRes,
          options.groundTruthProbes, "cell (m)", "method", "PVS faces", "seen", "mean PVS/seen",
          "median ratio", "ms/cell", "missing");
    for (float size : sizes) {
      const auto cells =
          streetCells(w, size, options.accuracyCells, options.seed + uint64_t(size * 10));
      // Every method and combination, on the same cells.
      struct Measured {
        Method method;
        std::vector<double> pvsSize, ms, ratio;
        size_t missing = 0;
      };
      std::vector<Measured> methods;
      for (const Method& m : benchMethods(horizon != nullptr))
        methods.push_back({m, {}, {}, {}, 0});
      std::vector<double> seen, probeOnly;
      for (size_t ci = 0; ci < cells.size(); ++ci) {
        const Box3f& cell = cells[ci];
        SampledVisibilityOptions gt =
            groundTruthOptions(w, options.groundTruthPoints, options.groundTruthRes);
        std::vector<PvsResult> results;
        std::vector<uint32_t> probes;  // every method's PVS: the truth aims at each face
        for (const Measured& m : methods) {
          results.push_back(w.pvs->compute(cell, m.method.options));
          probes.insert(probes.end(), results.back().faces.begin(), results.back().faces.end());
        }
        if (options.groundTruthProbes > 0) {
          std::sort(probes.begin(), probes.end());
          probes.erase(std::unique(probes.begin(), probes.end()), probes.end());
          gt.probeFaces = std::move(probes);
          gt.probeSamples = options.groundTruthProbes;
        }
        const SampledVisibility truth =
            sampleVisibleFaces(*w.oracleRays, *w.statics.triangles, cell, gt);
        seen.push_back(double(truth.faces.size()));
        probeOnly.push_back(double(truth.probeOnly));
        for (size_t mi = 0; mi < methods.size(); ++mi) {
          Measured& m = methods[mi];
          const PvsResult& r = results[mi];
          for (uint32_t f : truth.faces)
            m.missing += !std::binary_search(r.faces.begin(), r.faces.end(), f);
          m.pvsSize.push_back(double(r.faces.size()));
          m.ms.push_back(r.stats.timeMs);
          if (!truth.faces.empty())
            m.ratio.push_back(double(r.faces.size()) / double(truth.faces.size()));
        }
      }
      for (const Measured& m : methods) {
        const double seenMean = mean(seen);
        const double over = mean(m.pvsSize) / std::max(1.0, seenMean);
        const json row = {{"scene", spec},
                          {"method", m.method.name},
                          {"cell_size_m", size},
                          {"cells", m.pvsSize.size()},
                          {"pvs_faces", mean(m.pvsSize)},
                          {"seen_faces", seenMean},
                          {"seen_by_probes_only", mean(probeOnly)},
                          {"overestimation", over},
                          {"median_pvs_over_seen", median(m.ratio)},
                          {"ms_per_cell", median(m.ms)},
                          {"missing_faces", m.missing}};
        out["accuracy"].push_back(row);
        // The plot shows each scene's default: the horizons where they
        // run (`vistream-pvs cell --method auto`), else back faces.
        if (std::string(m.method.name) == (horizon ? "+horizons" : "+back faces"))
          lines.push_back(fmt::format("{} {} {} {} {}", plotLabel(spec),
                                      horizon ? "horizons" : "back-faces", size, median(m.ratio),
                                      median(m.ms)));
        if (human)
          fmt::print("  {:>8.1f} {:<20} {:>10.0f} {:>10.0f} {:>14.2f} {:>12.2f} {:>10.2f} {:>8}\n",
                     size, m.method.name, mean(m.pvsSize), seenMean, over, median(m.ratio),
                     median(m.ms), m.missing);
      }
    }

    // ---- the horizons' knobs: accuracy against time ------------------------
    if (horizon) {
      // The same 4 m cells as above; candidates: the single-occluder PVS
      // with back faces; the truth aims at every candidate.
      const auto cells = streetCells(w, 4.0f, options.accuracyCells, options.seed + 40);
      std::vector<std::vector<uint32_t>> candidates, truths;
      PvsOptions single;
      single.fusion = false;
      for (const Box3f& cell : cells) {
        candidates.push_back(w.pvs->compute(cell, single).faces);
        SampledVisibilityOptions gt =
            groundTruthOptions(w, options.groundTruthPoints, options.groundTruthRes);
        gt.probeFaces = candidates.back();
        gt.probeSamples = std::max(1, options.groundTruthProbes);
        truths.push_back(sampleVisibleFaces(*w.oracleRays, *w.statics.triangles, cell, gt).faces);
      }
      // Occluders are shrunk by epsilon + bin margin, rounded up to whole
      // columns: the last rows shrink less (one column fewer on a 0.5 m
      // grid) at the price of more samples or more bins.
      // The last four rows are the defaults without chains of walls (each
      // wall line alone), without walls (solid columns only), then without
      // the walks' shortcuts (hiding hints, then block skipping too): the
      // time they save.
      auto knob = [](double epsilon, double binMargin, int azimuthBins, int refinements,
                     bool shortcuts = true, bool hints = true, bool walls = true,
                     bool chains = true) {
        HorizonFusionOptions o;
        o.epsilon = epsilon;
        o.binMargin = binMargin;
        o.azimuthBins = azimuthBins;
        o.refinements = refinements;
        o.skipBlocks = shortcuts;
        o.hidingHints = shortcuts && hints;
        o.walls = walls;
        o.wallChains = walls && chains;
        return o;
      };
      const HorizonFusionOptions knobs[] = {knob(2.0, 0.5, 1024, 1),
                                            knob(1.0, 0.5, 1024, 0),
                                            knob(1.0, 0.5, 1024, 1),
                                            knob(1.0, 0.5, 1024, 2),
                                            knob(0.5, 0.5, 1024, 1),
                                            knob(0.74, 0.25, 2048, 1),
                                            knob(0.74, 0.25, 1024, 2),
                                            knob(1.0, 0.5, 1024, 1, true, true, true, false),
                                            knob(1.0, 0.5, 1024, 1, true, true, false),
                                            knob(1.0, 0.5, 1024, 1, true, false),
                                            knob(1.0, 0.5, 1024, 1, false)};
      if (human)
        fmt::print(
            "\nOcclusion horizons' knobs ({}, the 4 m cells above; after the single occluders "
            "with back faces; default epsilon {} m, {} refinement)\n"
            "  {:>11} {:>10} {:>6} {:>11} {:>10} {:>12} {:>12} {:>10} {:>8} {:>6} {:>6} {:>6} "
            "{:>6}\n",
            spec, HorizonFusionOptions{}.epsilon, HorizonFusionOptions{}.refinements, "epsilon (m)",
            "margin (m)", "bins", "refinements", "reach (m)", "median ratio", "fusion ms",
            "build s", "missing", "walls", "chains", "hints", "skips");
      for (const HorizonFusionOptions& k : knobs) {
        const HorizonFusion fusion(w.scene, w.statics, k);
        std::vector<double> ratio, ms;
        size_t missing = 0;
        for (size_t ci = 0; ci < cells.size(); ++ci) {
          const HorizonFusionResult r = fusion.cull(cells[ci], candidates[ci]);
          for (uint32_t f : truths[ci])
            missing += !std::binary_search(r.faces.begin(), r.faces.end(), f);
          ms.push_back(r.stats.timeMs);
          if (!truths[ci].empty())
            ratio.push_back(double(r.faces.size()) / double(truths[ci].size()));
        }
        const double reach = 2.0 * k.binMargin / (2.0 * std::numbers::pi / k.azimuthBins) *
                             std::pow(double(HorizonFusion::kRefine), k.refinements);
        out["horizon_knobs"].push_back({{"scene", spec},
                                        {"epsilon_m", k.epsilon},
                                        {"bin_margin_m", k.binMargin},
                                        {"azimuth_bins", k.azimuthBins},
                                        {"refinements", k.refinements},
                                        {"reach_m", reach},
                                        {"median_pvs_over_seen", median(ratio)},
                                        {"fusion_ms_per_cell", median(ms)},
                                        {"build_s", fusion.prepareMs() / 1000.0},
                                        {"missing_faces", missing},
                                        {"walls", k.walls},
                                        {"wall_chains", k.wallChains},
                                        {"hiding_hints", k.hidingHints},
                                        {"skip_blocks", k.skipBlocks}});
        if (human)
          fmt::print(
              "  {:>11.2f} {:>10.2f} {:>6} {:>11} {:>10.0f} {:>12.2f} {:>12.2f} {:>10.1f} {:>8} "
              "{:>6} {:>6} {:>6} {:>6}\n",
              k.epsilon, k.binMargin, k.azimuthBins, k.refinements, reach, median(ratio),
              median(ms), fusion.prepareMs() / 1000.0, missing, k.walls ? "on" : "off",
              k.wallChains ? "on" : "off", k.hidingHints ? "on" : "off",
              k.skipBlocks ? "on" : "off");
      }
    }

    // ---- bake time for a district -------------------------------------------
    if (scratch) {
      BakeOptions bake;
      bake.cellSize = glm::vec3(bakeCell);
      bake.threads = options.bakeThreads;
      bake.region = districtRegion(w, bake, options.districtSize);
      const glm::vec3 extent = bake.region->extent();
      if (human)
        fmt::print(
            "\nBake time for a district ({}: {:.0f} m x {:.0f} m around the scene's centre, "
            "{:g} m cells, coarse to fine, {} thread{})\n"
            "  {:<20} {:>8} {:>10} {:>10} {:>16}\n",
            spec, extent.x, extent.z, bakeCell, options.bakeThreads,
            options.bakeThreads == 1 ? "" : "s (0: all cores)", "method", "cells", "bake (s)",
            "ms/cell", "mean PVS faces");
      for (const Method& m : benchMethods(horizon != nullptr)) {
        bake.pvs = m.options;
        const BakeReport r = bakePvs(w.scene, *w.pvs, w.statics.freeSpace, bake,
                                     scratch->path() / fmt::format("district-{}.db", bakes++));
        const double pvsFaces = r.shardCells ? double(r.totalFaces) / double(r.shardCells) : 0.0;
        out["bake"].push_back({{"scene", spec},
                               {"method", m.name},
                               {"cell_size_m", bakeCell},
                               {"district_m", {extent.x, extent.z}},
                               {"cells", r.shardCells},
                               {"bake_s", r.timeMs / 1000.0},
                               {"mean_cell_ms", r.meanCellMs},
                               {"mean_pvs_faces", pvsFaces},
                               {"threads", options.bakeThreads}});
        if (human)
          fmt::print("  {:<20} {:>8} {:>10.2f} {:>10.2f} {:>16.0f}\n", m.name, r.shardCells,
                     r.timeMs / 1000.0, r.meanCellMs, pvsFaces);
      }
    }
  }
  if (!options.plotDir.empty()) {
    std::filesystem::create_directories(options.plotDir);
    const auto dat = std::filesystem::path(options.plotDir) / "accuracy.dat";
    std::ofstream f(dat);
    f << "# scene method cell_size_m median_pvs_over_seen ms_per_cell (the default method)\n";
    for (const auto& l : lines) f << l << "\n";
    f.close();
    const auto gp = std::filesystem::path(options.plotDir) / "accuracy.gp";
    std::ofstream g(gp);
    g << "set terminal pngcairo size 1000,480\nset output '"
      << (std::filesystem::path(options.plotDir) / "accuracy.png").string()
      << "'\nset multiplot layout 1,2 title 'PVS accuracy against time, default method "
         "(horizons in cities, back faces indoors)'\nset logscale x 2\nset logscale y\n"
         "set grid\nset xlabel 'cell size (m)'\nset key outside bottom center horizontal\n"
         "set ylabel 'median PVS / seen faces'\nplot 1.5 with lines dashtype 2 lc 'gray' "
         "title 'target 1.5'";
    for (const auto& s : options.scenes)
      g << ", '" << dat.string() << "' using (strcol(1) eq '" << plotLabel(s)
        << "' ? $3 : 1/0):4 with linespoints title '" << plotLabel(s) << "'";
    g << "\nset ylabel 'ms per cell'\nplot 20 with lines dashtype 2 lc 'gray' title '20 ms'";
    for (const auto& s : options.scenes)
      g << ", '" << dat.string() << "' using (strcol(1) eq '" << plotLabel(s)
        << "' ? $3 : 1/0):5 with linespoints title '" << plotLabel(s) << "'";
    g << "\nunset multiplot\n";
    g.close();
    const std::string cmd = "gnuplot '" + gp.string() + "' 2>/dev/null";
    if (std::system(cmd.c_str()) != 0)
      spdlog::warn("gnuplot not available: wrote {} only", dat.string());
  }
  out["total_s"] = total.ms() / 1000.0;
  if (human)
    fmt::print("\nbench run time: {:.0f} s\n", total.ms() / 1000.0);
  else
    std::cout << out.dump(2) << "\n";
  return 0;
}

}  // namespace vistream
