#include "server/cmd/pvs_commands.h"

#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "common/core/error.h"
#include "common/core/log.h"
#include "common/core/parse.h"
#include "common/generate/scene_spec.h"
#include "server/visibility/epsilon_pvs.h"

namespace vistream {
namespace {

using nlohmann::json;

Box3f parseCell(const Scene& scene, const std::string& text) {
  const auto v = parseNumberList(text, 6, "--cell");
  if (v[0] > v[3] || v[1] > v[4] || v[2] > v[5])
    throwInputError("--cell: expected x0,y0,z0,x1,y1,z1 with x0<=x1, y0<=y1, z0<=z1, got '{}'", text);
  return Box3f(scene.toLocal({v[0], v[1], v[2]}), scene.toLocal({v[3], v[4], v[5]}));
}

json statsJson(const PvsStats& s) {
  return json{{"time_ms", s.timeMs},
              {"box_stage_ms", s.boxStageMs},
              {"face_stage_ms", s.faceStageMs},
              {"occluders", s.occluders},
              {"occluders_used", s.occludersUsed},
              {"lines_cast", s.linesCast},
              {"line_box_tests", s.lineBoxTests},
              {"line_polygon_tests", s.linePolygonTests},
              {"boxes", s.boxes},
              {"boxes_occluded", s.boxesOccluded},
              {"boxes_occluded_by_first_occluder", s.boxesOccludedByFirst},
              {"faces_total", s.faces},
              {"faces_occluded", s.facesOccluded},
              {"faces_culled_by_box_stage", s.facesCulledByBoxStage}};
}

int cmdCell(const std::string& spec, const std::string& cellText, const std::string& method,
            const PvsOptions& options, bool asJson) {
  if (method != "paper" && method != "fused")
    throwInputError("--method: expected 'paper' or 'fused', got '{}'", method);
  if (method == "fused") throwInputError("--method fused is not available yet");
  const Scene scene = openScene(spec);
  const Box3f cell = parseCell(scene, cellText);
  const EpsilonPvs pvs(scene);
  const PvsResult r = pvs.compute(cell, options);
  if (asJson) {
    json objects = json::array();
    for (uint32_t o : r.objects) objects.push_back(scene.objects[o].name);
    std::cout << json{{"faces", r.faces}, {"objects", objects}, {"stats", statsJson(r.stats)}}.dump() << "\n";
    return 0;
  }
  const PvsStats& s = r.stats;
  fmt::print("PVS of cell {}: {} of {} faces ({:.1f}% culled), {} objects\n", cellText, r.faces.size(),
             scene.faceCount, 100.0 * double(s.facesOccluded) / double(std::max<size_t>(1, s.faces)), r.objects.size());
  fmt::print("  {:<34} {:>12.3f}\n", "time (ms)", s.timeMs);
  fmt::print("  {:<34} {:>12.3f}\n", "  box stage (ms)", s.boxStageMs);
  fmt::print("  {:<34} {:>12.3f}\n", "  face stage (ms)", s.faceStageMs);
  fmt::print("  {:<34} {:>12}\n", "occluders (available / used)", fmt::format("{} / {}", s.occluders, s.occludersUsed));
  fmt::print("  {:<34} {:>12}\n", "lines cast", s.linesCast);
  fmt::print("  {:<34} {:>12}\n", "line/box tests", s.lineBoxTests);
  fmt::print("  {:<34} {:>12}\n", "line/polygon tests", s.linePolygonTests);
  fmt::print("  {:<34} {:>12}\n", "boxes (occluded / total)", fmt::format("{} / {}", s.boxesOccluded, s.boxes));
  fmt::print("  {:<34} {:>12}\n", "faces culled by box stage", s.facesCulledByBoxStage);
  return 0;
}

}  // namespace

int runPvsTool(int argc, char** argv) {
  CLI::App app{"vistream-pvs: conservative potentially visible sets of view cells "
               "(Cohen-Or and Zadicario 1998).\nA SCENE is a file (.obj, .gltf, .glb, .json manifest) "
               "or a built-in name (city1, city2, bigcity, interior, terrain)."};
  app.require_subcommand(1);
  app.fallthrough();  // --log-level may follow the subcommand
  std::string logLevel;
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");

  auto* cell = app.add_subcommand("cell", "the PVS of one view cell");
  std::string scene, cellText, method = "paper";
  bool asJson = false, noBbox = false, noIncremental = false, noRedundantOccluders = false,
       noRedundantRays = false;
  size_t largeOccluders = 0;
  cell->add_option("--scene", scene, "SCENE")->required();
  cell->add_option("--cell", cellText, "x0,y0,z0,x1,y1,z1 in file coordinates")->required();
  cell->add_option("--method", method, "paper (single convex occluders) or fused");
  cell->add_flag("--no-bbox", noBbox, "skip the bounding-box stage");
  cell->add_flag("--no-incremental", noIncremental, "every line traverses the space on its own");
  cell->add_flag("--no-redundant-occluders", noRedundantOccluders, "keep occluded objects as occluders");
  cell->add_flag("--no-redundant-rays", noRedundantRays, "cast every corner-vertex line");
  cell->add_option("--large-occluders", largeOccluders, "use only the K largest occluders by solid angle (0: all)");
  cell->add_flag("--json", asJson, "one JSON object on stdout: faces, objects, stats");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    initLogging(logLevel);
    if (*cell) {
      PvsOptions options;
      options.boxStage = !noBbox;
      options.incremental = !noIncremental;
      options.dropOccludedOccluders = !noRedundantOccluders;
      options.removeRedundantLines = !noRedundantRays;
      options.largeOccluders = largeOccluders;
      return cmdCell(scene, cellText, method, options, asJson);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vistream-pvs: error: %s\n", e.what());
    return 1;
  }
  return 2;
}

}  // namespace vistream
