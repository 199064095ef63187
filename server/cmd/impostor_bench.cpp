#include "server/cmd/impostor_bench.h"

#include <fmt/format.h>

#include <algorithm>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numeric>

#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/generate/scene_spec.h"
#include "server/cmd/scene_boxes.h"
#include "server/impostor/impostor_world.h"

namespace vistream {
namespace {

using nlohmann::json;

struct Bake {
  ImpostorStats stats;  // of the last run, with the median time
};

Bake bakeMedian(const ImpostorWorld& world, const Box3f& cell, const ImpostorSite& site,
                const ImpostorOptions& options, size_t repeats) {
  std::vector<double> seconds;
  Bake b;
  for (size_t r = 0; r < repeats; ++r) {
    bakeImpostor(world.view(), cell, site.box, site.triangles, options, &b.stats);
    seconds.push_back(b.stats.seconds);
  }
  b.stats.seconds = median(seconds);
  return b;
}

json statsRow(const ImpostorStats& s) {
  return {{"points", s.points},
          {"points_per_pixel", s.pointsPerPixel},
          {"screen_pixels", s.screenPixels},
          {"covered_pixels", s.coveredPixels},
          {"bytes", s.bytes},
          {"memory_mb", double(s.bytesUncompressed) / 1e6},
          {"single_colour_share", s.points ? double(s.singleColour) / double(s.points) : 0.0},
          {"appearance_rays", s.appearanceRays},
          {"bake_s", s.seconds}};
}

}  // namespace

ImpostorBenchOptions defaultImpostorBenchOptions() {
  ImpostorBenchOptions o;
  o.scenes = {
      "bigcity",
      (std::filesystem::path(VISTREAM_DEFAULT_AVATAR).parent_path() / "delfshaven.obj").string()};
  o.cell = "0,1,0,4,3,4";
  // Lower than the bake's default, so that the real city's street cell (5,448
  // far-field triangles in 11 sector-bands) has three impostors to measure.
  o.placement.minTriangles = 300;
  return o;
}

int runImpostorBench(const ImpostorBenchOptions& options) {
  const Box3d fileCell = parseFileBox(options.cell, "--cell");
  json out = json::array();
  for (const std::string& spec : options.scenes) {
    const Scene scene = openScene(spec);
    warnIfOutsideScene(scene, fileCell, "--cell", options.cell);
    const Box3f cell = toLocal(scene, fileCell);
    const ImpostorWorld world(scene, {GroundChoice{}, LightingOptions{}, options.lightingCache});
    const ImpostorPlacementOptions& placement = options.placement;
    const ImpostorPlacement placed =
        placeImpostors(cell, world.triangles(), world.pvsTriangles(cell), placement);
    // The three sites with the most triangles (ties: placement order).
    std::vector<size_t> order(placed.sites.size());
    std::iota(order.begin(), order.end(), size_t(0));
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return placed.sites[a].triangles.size() > placed.sites[b].triangles.size();
    });
    order.resize(std::min<size_t>(3, order.size()));
    json sceneOut = {{"scene", scene.name},
                     {"cell", options.cell},
                     {"fov_deg", options.screen.vfovDeg},
                     {"why", placed.why}};
    ImpostorOptions defaults;
    defaults.screen = options.screen;
    std::vector<std::pair<std::string, ImpostorOptions>> sweep;
    if (options.sweep && !order.empty()) {
      for (float f : {0.5f, 0.7f, 0.8f, 1.0f, 1.4f}) {
        ImpostorOptions o = defaults;
        o.resolutionFactor = f;
        sweep.emplace_back(fmt::format("resolution {:.1f}", f), o);
      }
      ImpostorOptions o = defaults;
      o.removePoints = false;
      sweep.emplace_back("no point removal", o);
      o = defaults;
      o.cullHidden = false;
      sweep.emplace_back("hidden points kept", o);
      for (auto [w, h] : {std::pair{1u, 1u}, {4u, 2u}, {8u, 2u}, {16u, 4u}}) {
        o = defaults;
        o.textureWidth = w;
        o.textureHeight = h;
        sweep.emplace_back(fmt::format("texture {}x{}", w, h), o);
      }
      for (float v : {2.0f, 4.0f, 8.0f}) {
        o = defaults;
        o.varianceThreshold = v;
        sweep.emplace_back(fmt::format("variance {:g}", v), o);
      }
      o = defaults;
      o.pixelFilterSigma = 0.5f;  // the thesis's Gaussian
      sweep.emplace_back("pixel filter 0.5", o);
    }
    ProgressBar bar(fmt::format("impostor-bench {}", scene.name),
                    (order.size() + sweep.size()) * options.repeats);
    json table = json::array();
    for (size_t k : order) {
      const ImpostorSite& site = placed.sites[k];
      const Bake b = bakeMedian(world, cell, site, defaults, options.repeats);
      bar.advance(options.repeats);
      json row = statsRow(b.stats);
      row["sector"] = site.sector;
      row["band"] = site.band;
      row["triangles"] = site.triangles.size();
      row["geometry_bytes"] = world.geometryBytes(world.replacedFaces(site.triangles));
      table.push_back(row);
    }
    json sweepOut = json::array();
    for (const auto& [name, o] : sweep) {
      const Bake b = bakeMedian(world, cell, placed.sites[order[0]], o, options.repeats);
      bar.advance(options.repeats);
      json row = statsRow(b.stats);
      row["setting"] = name;
      sweepOut.push_back(row);
    }
    bar.finish();
    sceneOut["table_5_1"] = table;
    sceneOut["sweep"] = sweepOut;
    out.push_back(sceneOut);
    if (options.json) continue;
    fmt::print("\n{} cell {}: {}\n", scene.name, options.cell, placed.why);
    if (table.empty()) continue;
    fmt::print(
        "Table 5.1 (screen {}x{}, vertical field of view {:g} degrees; bake times are "
        "medians of {} runs)\n",
        options.screen.width, options.screen.height, options.screen.vfovDeg, options.repeats);
    fmt::print("  {:<34}", "");
    for (size_t i = 0; i < table.size(); ++i)
      fmt::print(" {:>14}", fmt::format("impostor {} ({}/{})", i + 1, table[i]["sector"].get<int>(),
                                        table[i]["band"].get<int>()));
    fmt::print("\n");
    auto line = [&](const char* label, auto value) {
      fmt::print("  {:<34}", label);
      for (const json& row : table) fmt::print(" {:>14}", value(row));
      fmt::print("\n");
    };
    line("triangles replaced",
         [](const json& r) { return fmt::format("{}", r["triangles"].get<size_t>()); });
    line("#points", [](const json& r) { return fmt::format("{}", r["points"].get<uint64_t>()); });
    line("#points/screen pixel",
         [](const json& r) { return fmt::format("{:.2f}", r["points_per_pixel"].get<double>()); });
    line("approx. #screen pixels",
         [](const json& r) { return fmt::format("{}", r["screen_pixels"].get<uint64_t>()); });
    line("bake time (s)",
         [](const json& r) { return fmt::format("{:.1f}", r["bake_s"].get<double>()); });
    line("memory, no single colours (MB)",
         [](const json& r) { return fmt::format("{:.2f}", r["memory_mb"].get<double>()); });
    line("encoded bytes",
         [](const json& r) { return fmt::format("{}", r["bytes"].get<uint64_t>()); });
    line("geometry bytes replaced",
         [](const json& r) { return fmt::format("{}", r["geometry_bytes"].get<size_t>()); });
    if (sweepOut.empty()) continue;
    fmt::print("Knobs on impostor 1 (one changed at a time)\n");
    fmt::print("  {:<20} {:>9} {:>8} {:>10} {:>8} {:>12} {:>8}\n", "setting", "points", "pts/px",
               "bytes", "single", "PIF rays", "bake s");
    for (const json& r : sweepOut)
      fmt::print("  {:<20} {:>9} {:>8.2f} {:>10} {:>7.0f}% {:>12} {:>8.2f}\n",
                 r["setting"].get<std::string>(), r["points"].get<uint64_t>(),
                 r["points_per_pixel"].get<double>(), r["bytes"].get<uint64_t>(),
                 100.0 * r["single_colour_share"].get<double>(),
                 r["appearance_rays"].get<uint64_t>(), r["bake_s"].get<double>());
  }
  if (options.json) std::cout << out.dump() << "\n";
  return 0;
}

}  // namespace vistream
