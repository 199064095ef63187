#include "server/cmd/walk_bench.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/generate/path.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/world/free_space.h"
#include "common/world/static_world.h"
#include "server/visibility/hierarchical_culling.h"

namespace vistream {
namespace {

using json = nlohmann::json;

struct WalkMeans {
  double tests = 0, propagated = 0, skipped = 0, cullMs = 0, frameMs = 0, faces = 0;
};

// Runs one viewer over the path `repeats` times (same seed, so the same
// classifications); counts are per frame, times are medians of the runs' means.
WalkMeans walk(const CullingScene& culling, const std::vector<PathSample>& path, CullingOptions o,
               size_t repeats) {
  std::vector<double> cull, frame;
  WalkMeans m;
  for (size_t rep = 0; rep < repeats; ++rep) {
    CullingViewer viewer(culling, o);
    WalkMeans run;
    for (const auto& s : path) {
      const FrameResult r = viewer.frame(s.position, s.yawDeg, s.pitchDeg);
      run.tests += double(r.nodeTests);
      run.propagated += double(r.propagated);
      run.skipped += double(r.skipped);
      run.cullMs += r.cullingMs;
      run.frameMs += r.cullingMs + double(r.visibleFaces) * culling.drawMsPerFace();
      run.faces += double(r.visibleFaces);
    }
    const double n = double(std::max<size_t>(1, path.size()));
    cull.push_back(run.cullMs / n);
    frame.push_back(run.frameMs / n);
    m = {run.tests / n, run.propagated / n, run.skipped / n, 0, 0, run.faces / n};
  }
  m.cullMs = median(cull);
  m.frameMs = median(frame);
  return m;
}

void writePlots(const std::string& dir, const std::string& spec, const json& sceneOut) {
  std::filesystem::create_directories(dir);
  const auto base = std::filesystem::path(dir) / ("walk_" + spec);
  const std::string speedDat = base.string() + "_speed.dat", skipDat = base.string() + "_pskip.dat";
  {
    // One block per method (gnuplot's "index"), in the order plotted.
    std::ofstream f(speedDat);
    f << "# speed node_tests culling_ms frame_ms, one block per method: A B C D adaptive\n";
    for (const char* m : {"A", "B", "C", "D", "adaptive"}) {
      for (const auto& r : sceneOut["speeds"])
        if (r["method"] == m)
          f << r["speed"].get<double>() << " " << r["node_tests"].get<double>() << " "
            << r["culling_ms"].get<double>() << " " << r["frame_ms"].get<double>() << "\n";
      f << "\n\n";
    }
    std::ofstream g(skipDat);
    g << "# p_skip frame_ms node_tests\n";
    for (const auto& r : sceneOut["p_skip"])
      g << r["p_skip"].get<double>() << " " << r["frame_ms"].get<double>() << " "
        << r["node_tests"].get<double>() << "\n";
  }
  const std::string gp = base.string() + ".gp";
  std::ofstream g(gp);
  g << "set terminal pngcairo size 1100,800\nset output '" << base.string() << ".png'\n"
    << "set multiplot layout 2,2 title '" << spec << ": Bittner and Havran 2001, Figures 8-11'\n"
    << "set logscale x 2\nset xlabel 'relative walking speed'\nset key top left\n";
  const char* methods[] = {"A", "B", "C", "D", "adaptive"};
  const char* columns[][2] = {
      {"2", "node visibility tests"}, {"3", "culling time (ms)"}, {"4", "frame time (ms)"}};
  for (const auto& c : columns) {
    g << "set ylabel '" << c[1] << "'\nplot ";
    for (size_t m = 0; m < std::size(methods); ++m)
      g << (m ? ", " : "") << "'" << speedDat << "' index " << m << " using 1:" << c[0]
        << " with linespoints title '" << methods[m] << "'";
    g << "\n";
  }
  g << "unset logscale x\nset xlabel 'p_{skip} (method D, speed 1.0)'\nset ylabel 'frame time "
       "(ms)'\n"
    << "plot '" << skipDat << "' using 1:2 with linespoints title 'D'\nunset multiplot\n";
  g.close();
  const std::string cmd = "gnuplot '" + gp + "' 2>/dev/null";
  if (std::system(cmd.c_str()) != 0)
    spdlog::warn("gnuplot not available: wrote the .dat files only");
}

}  // namespace

int runWalkBench(const WalkBenchOptions& options) {
  json out = json::array();
  const std::vector<double> speeds = {0.25, 0.5, 1.0, 2.0, 4.0};
  const std::vector<CullingMethod> methods = {
      CullingMethod::Classical, CullingMethod::HierarchyUpdating, CullingMethod::Propagation,
      CullingMethod::Conservative, CullingMethod::Adaptive};
  const bool human = !options.json;
  for (const std::string& spec : options.scenes) {
    const Scene scene = openScene(spec);
    const CullingScene culling(scene);
    const size_t occluders =
        options.occluders ? options.occluders : (spec.rfind("interior2", 0) == 0 ? 32 : 16);
    const FreeSpace fs = buildStaticWorld(scene).freeSpace;
    auto walkPath = [&](double speed) {
      PathOptions po;
      po.speed = speed;
      po.frames = options.frames;
      po.seed = 7;
      auto path = generatePath(scene, fs, po);
      for (auto& p : path) p.position = glm::dvec3(scene.toLocal(p.position));
      return path;
    };
    auto optionsFor = [&](CullingMethod m, double pSkip) {
      CullingOptions o;
      o.method = m;
      o.occluders = occluders;
      o.pSkip = pSkip;
      o.pVp = 0.5;
      return o;
    };
    json sceneOut = {{"scene", spec},
                     {"kd_nodes", culling.tree().nodes().size()},
                     {"occluders", occluders},
                     {"frames", options.frames},
                     {"draw_ms_per_face", culling.drawMsPerFace()},
                     {"cost_model", "frame_ms = culling_ms + visible_faces * draw_ms_per_face"}};
    if (human)
      fmt::print(
          "\n{}: {} kD-tree nodes, {} occluders, {} frames per path, draw cost {:.2e} ms/face, "
          "times are medians of {} runs\n"
          "  {:>6} {:>8} {:>10} {:>10} {:>8} {:>10} {:>10} {:>9} {:>12} {:>10}\n",
          spec, culling.tree().nodes().size(), occluders, options.frames, culling.drawMsPerFace(),
          options.repeats, "speed", "method", "node tests", "propagated", "skipped", "culling ms",
          "frame ms", "faces", "tests saved", "faces/A");
    ProgressBar progress(fmt::format("walk-bench {}", spec), speeds.size() * (methods.size() + 10));
    for (double speed : speeds) {
      const auto path = walkPath(speed);
      WalkMeans a{};
      for (CullingMethod m : methods) {
        const WalkMeans r = walk(culling, path, optionsFor(m, 0.5), options.repeats);
        progress.advance();
        if (m == CullingMethod::Classical) a = r;
        const double saved = 1.0 - r.tests / std::max(1e-9, a.tests),
                     over = r.faces / std::max(1e-9, a.faces);
        sceneOut["speeds"].push_back({{"speed", speed},
                                      {"method", cullingMethodName(m)},
                                      {"node_tests", r.tests},
                                      {"propagated", r.propagated},
                                      {"skipped", r.skipped},
                                      {"culling_ms", r.cullMs},
                                      {"frame_ms", r.frameMs},
                                      {"visible_faces", r.faces},
                                      {"node_tests_saved_vs_A", saved},
                                      {"faces_over_A", over}});
        if (human)
          fmt::print(
              "  {:>6.2f} {:>8} {:>10.1f} {:>10.1f} {:>8.1f} {:>10.3f} {:>10.3f} {:>9.0f} "
              "{:>11.1f}% {:>10.3f}\n",
              speed, cullingMethodName(m), r.tests, r.propagated, r.skipped, r.cullMs, r.frameMs,
              r.faces, 100.0 * saved, over);
      }
      // Fixed p_skip against adaptive: the best fixed value at this speed.
      double bestP = 0.0, bestMs = 1e30;
      for (int i = 0; i <= 9; ++i) {
        const double p = 0.1 * i;
        const WalkMeans r =
            walk(culling, path, optionsFor(CullingMethod::Conservative, p), options.repeats);
        progress.advance();
        if (speed == 1.0)
          sceneOut["p_skip"].push_back({{"p_skip", p},
                                        {"node_tests", r.tests},
                                        {"culling_ms", r.cullMs},
                                        {"frame_ms", r.frameMs},
                                        {"visible_faces", r.faces},
                                        {"faces_over_A", r.faces / std::max(1e-9, a.faces)}});
        if (r.frameMs < bestMs) bestMs = r.frameMs, bestP = p;
      }
      const json& adaptiveRow = sceneOut["speeds"].back();
      sceneOut["adaptive_vs_best_fixed"].push_back(
          {{"speed", speed},
           {"best_fixed_p_skip", bestP},
           {"best_fixed_frame_ms", bestMs},
           {"adaptive_frame_ms", adaptiveRow["frame_ms"]},
           {"A_frame_ms", a.frameMs},
           {"adaptive_over_best_fixed", adaptiveRow["frame_ms"].get<double>() / bestMs}});
    }
    progress.finish();
    if (human) {
      fmt::print(
          "  method D at speed 1.0 against p_skip (p_vp 0.5), Figure 11:\n  {:>6} {:>12} {:>12} "
          "{:>12} {:>10}\n",
          "p_skip", "node tests", "culling ms", "frame ms", "faces/A");
      for (const auto& r : sceneOut["p_skip"])
        fmt::print("  {:>6.1f} {:>12.1f} {:>12.3f} {:>12.3f} {:>10.3f}\n",
                   r["p_skip"].get<double>(), r["node_tests"].get<double>(),
                   r["culling_ms"].get<double>(), r["frame_ms"].get<double>(),
                   r["faces_over_A"].get<double>());
      fmt::print(
          "  adaptive against the best fixed p_skip (D) at each speed:\n  {:>6} {:>12} {:>14} "
          "{:>14} {:>12} {:>10}\n",
          "speed", "best p_skip", "best fixed ms", "adaptive ms", "A ms", "ratio");
      for (const auto& r : sceneOut["adaptive_vs_best_fixed"])
        fmt::print("  {:>6.2f} {:>12.1f} {:>14.3f} {:>14.3f} {:>12.3f} {:>10.3f}\n",
                   r["speed"].get<double>(), r["best_fixed_p_skip"].get<double>(),
                   r["best_fixed_frame_ms"].get<double>(), r["adaptive_frame_ms"].get<double>(),
                   r["A_frame_ms"].get<double>(), r["adaptive_over_best_fixed"].get<double>());
    }
    if (!options.plotDir.empty()) writePlots(options.plotDir, spec, sceneOut);
    out.push_back(std::move(sceneOut));
  }
  if (!human) std::cout << out.dump(2) << "\n";
  return 0;
}

}  // namespace vistream
