// vistream-client-bench: what the far-field pipeline's accuracy costs in
// time (Wimmer 2001, chapter 4: Figures 4.8 and 4.9, Table 4.1).
//
// For each scene it walks one generated path (headless, software near field)
// and renders every frame with raycast-all (the reference image and the first
// baseline) and geometry-all (full polygon rendering, the second baseline),
// then the pipeline with each accuracy knob varied on its own around the
// defaults: near-field distance d, pixel budget, cache on/off, height-field
// cell size and horizon subsampling. Each configuration runs `--repeats`
// times over the whole path; frame times are medians over the repeats of the
// mean frame time of a run. Error: share of pixels differing from the
// reference and mean colour error, averaged over frames.
#include "client/cmd/client_bench_commands.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "client/app/walkthrough.h"
#include "client/cmd/shadow_bench.h"
#include "client/farfield/pipeline.h"
#include "common/cmd/cli.h"
#include "common/core/error.h"
#include "common/core/log.h"
#include "common/core/median.h"
#include "common/core/progress.h"
#include "common/core/stats_output.h"
#include "common/core/timer.h"
#include "common/generate/path.h"
#include "common/generate/scene_spec.h"

namespace vistream {
namespace {

using json = nlohmann::json;

struct BenchArgs {
  std::string scenes = "bigcity,terrain", size = "640x480", plotDir, logLevel = "warn";
  size_t frames = 120;
  int repeats = 3;
  double speed = 1.0;
  bool json = false, quick = false;
  bool shadows = false;
  ShadowBenchArgs shadow;
};

struct Config {
  std::string knob, value;
  PipelineOptions options;
};

struct Result {
  Config config;
  double frameMs = 0.0;            // median over repeats of the mean frame time
  std::vector<double> perFrameMs;  // from the median run
  double differing = 0.0, colourError = 0.0;
  PixelCounts meanPixels;
  std::vector<PixelCounts> perFrame;
};

Result runConfig(const RenderGeometry& g, const std::vector<Camera>& cams, const Config& c,
                 const std::vector<ImageRgb8>* reference, int repeats) {
  Result r;
  r.config = c;
  std::vector<double> means;
  std::vector<std::vector<double>> series;
  ImageRgb8 image;
  for (int rep = 0; rep < repeats; ++rep) {
    FrameRenderer renderer(g, c.options);
    std::vector<double> ms;
    double diff = 0.0, err = 0.0;
    std::vector<PixelCounts> pixels;
    for (size_t i = 0; i < cams.size(); ++i) {
      const FrameReport f = renderer.render(cams[i], image);
      ms.push_back(f.ms.total);
      pixels.push_back(f.pixels);
      if (reference && rep == 0) {
        const ImageDifference d = compareImages(image, (*reference)[i]);
        diff += d.differingFraction;
        err += d.meanColourError;
      }
    }
    if (rep == 0) {
      const double n = double(std::max<size_t>(1, cams.size()));
      r.differing = diff / n;
      r.colourError = err / n;
      r.perFrame = pixels;
      for (const PixelCounts& p : pixels) r.meanPixels += p;
      for (size_t* v : {&r.meanPixels.polygon, &r.meanPixels.horizon, &r.meanPixels.cache,
                        &r.meanPixels.rayHit, &r.meanPixels.rayMiss, &r.meanPixels.background})
        *v = size_t(double(*v) / n + 0.5);
    }
    double sum = 0.0;
    for (double m : ms) sum += m;
    means.push_back(sum / double(std::max<size_t>(1, ms.size())));
    series.push_back(std::move(ms));
  }
  r.frameMs = median(means);
  // The series of the run whose mean is the median.
  for (size_t i = 0; i < means.size(); ++i)
    if (means[i] == r.frameMs) r.perFrameMs = series[i];
  if (r.perFrameMs.empty() && !series.empty()) r.perFrameMs = series.front();
  return r;
}

json resultJson(const Result& r, double raycastMs, double geometryMs) {
  return {{"knob", r.config.knob},
          {"value", r.config.value},
          {"frame_ms", r.frameMs},
          {"speedup_vs_raycast_all", raycastMs / r.frameMs},
          {"speedup_vs_geometry_all", geometryMs / r.frameMs},
          {"differing_fraction", r.differing},
          {"mean_colour_error", r.colourError},
          {"pixels", statsJson(r.meanPixels)}};
}

// Table 4.1: min / average / max share of each pixel class over the frames.
json table41(const std::vector<PixelCounts>& frames, size_t pixelsPerFrame) {
  json t = json::object();
  const std::pair<const char*, size_t PixelCounts::*> classes[] = {
      {"ray_hit", &PixelCounts::rayHit},
      {"ray_miss", &PixelCounts::rayMiss},
      {"cache", &PixelCounts::cache},
      {"horizon", &PixelCounts::horizon},
      {"polygon", &PixelCounts::polygon}};
  for (const auto& [name, member] : classes) {
    double lo = 1e300, hi = 0, sum = 0;
    for (const PixelCounts& p : frames) {
      const double v = double(p.*member);
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      sum += v;
    }
    const double n = double(std::max<size_t>(1, frames.size())), total = double(pixelsPerFrame);
    t[name] = {{"min_pct", 100.0 * lo / total},
               {"avg_pct", 100.0 * sum / n / total},
               {"max_pct", 100.0 * hi / total},
               {"avg_count", sum / n}};
  }
  return t;
}

void writePlots(const std::string& dir, const std::string& scene,
                const std::vector<Result>& results, const Result& raycast, const Result& geometry,
                const Result& nearOnly) {
  std::filesystem::create_directories(dir);
  const auto base = std::filesystem::path(dir) / ("client_" + scene);
  // Figure 4.8: per-frame times of the baselines and the pipeline.
  {
    std::ofstream f(base.string() + "_frames.dat");
    f << "# frame geometry_all_ms pipeline_ms near_field_only_ms raycast_all_ms\n";
    const Result* def = nullptr;
    for (const Result& r : results)
      if (r.config.knob == "default") def = &r;
    for (size_t i = 0; def && i < def->perFrameMs.size(); ++i)
      f << i << " " << geometry.perFrameMs[i] << " " << def->perFrameMs[i] << " "
        << nearOnly.perFrameMs[i] << " " << raycast.perFrameMs[i] << "\n";
  }
  // Figure 4.9: per-frame times for each near-field distance.
  std::vector<const Result*> dRuns;
  for (const Result& r : results)
    if (r.config.knob == "near_distance") dRuns.push_back(&r);
  {
    std::ofstream f(base.string() + "_distance.dat");
    f << "# frame, then frame ms per near-field distance:";
    for (const Result* r : dRuns) f << " d=" << r->config.value;
    f << "\n";
    for (size_t i = 0; !dRuns.empty() && i < dRuns.front()->perFrameMs.size(); ++i) {
      f << i;
      for (const Result* r : dRuns) f << " " << r->perFrameMs[i];
      f << "\n";
    }
  }
  // Accuracy against time, one block per knob.
  std::vector<std::string> knobs;
  for (const Result& r : results)
    if (r.config.knob != "default" &&
        std::find(knobs.begin(), knobs.end(), r.config.knob) == knobs.end())
      knobs.push_back(r.config.knob);
  {
    std::ofstream f(base.string() + "_accuracy.dat");
    f << "# frame_ms differing_pct, one block per knob:";
    for (const std::string& k : knobs) f << " " << k;
    f << "\n";
    for (const std::string& k : knobs) {
      for (const Result& r : results)
        if (r.config.knob == k)
          f << r.frameMs << " " << 100.0 * r.differing << " " << r.config.value << "\n";
      f << "\n\n";
    }
  }
  std::ofstream g(base.string() + ".gp");
  g << "set terminal pngcairo size 1200,900 noenhanced\nset output '" << base.string() << ".png'\n"
    << "set multiplot layout 2,2 title '" << scene
    << ": Wimmer 2001, Figures 4.8 and 4.9, accuracy against time'\n"
    << "set xlabel 'frame'\nset ylabel 'frame time (ms)'\nset logscale y\nset key top left\n"
    << "plot '" << base.string()
    << "_frames.dat' using 1:2 with lines title 'geometry-all', '' using 1:3 with lines "
    << "title 'pipeline', '' using 1:4 with lines title 'near field only', '' using 1:5 with lines "
       "title 'raycast-all'\n"
    << "plot ";
  for (size_t i = 0; i < dRuns.size(); ++i)
    g << (i ? ", " : "") << "'" << base.string() << "_distance.dat' using 1:" << i + 2
      << " with lines title 'd = " << dRuns[i]->config.value << " m'";
  g << "\nunset logscale y\nset xlabel 'frame time (ms)'\nset ylabel 'pixels differing from "
       "raycast-all (%)'\n"
    << "plot ";
  for (size_t i = 0; i < knobs.size(); ++i)
    g << (i ? ", " : "") << "'" << base.string() << "_accuracy.dat' index " << i
      << " using 1:2 with linespoints title '" << knobs[i] << "'";
  g << "\nunset multiplot\n";
  g.close();
  const std::string cmd = "gnuplot '" + base.string() + ".gp' 2>/dev/null";
  if (std::system(cmd.c_str()) != 0)
    spdlog::warn("gnuplot not available: wrote the .dat files only");
}

int runBench(const BenchArgs& a) {
  const glm::ivec2 size = parseImageSize(a.size);
  // --repeats, --frames and --speed are range-checked at parse time.
  json out = json::array();
  for (const std::string& spec : splitCommaList(a.scenes)) {
    const Scene scene = openScene(spec);
    const RenderGeometry g = renderGeometryFromScene(scene);
    PathOptions po;
    po.frames = a.frames;
    po.speed = a.speed;
    const std::vector<PathSample> path = generatePath(scene, po);
    const std::vector<Camera> cams = camerasFromPath(path, scene.origin, size.x, size.y, 60.0f);
    // The knob sweeps run the thesis's pipeline whatever the scene's size
    // (polygon budget 0); the "auto" row shows what the client decides.
    PipelineOptions base;
    base.polygonBudget = 0;
    base.nearDistance = scene.environment.nearFieldRadius;
    base.horizonAllowed = scene.environment.sky != SkyMode::None;

    // Reference images, and the raycast-all baseline.
    std::vector<ImageRgb8> reference(cams.size());
    Config rc{"baseline", "raycast-all", base};
    rc.options.mode = RenderMode::RaycastAll;
    {
      FrameRenderer ref(g, rc.options);
      ProgressBar bar(fmt::format("{}: reference frames", spec), cams.size());
      for (size_t i = 0; i < cams.size(); ++i) {
        (void)ref.render(cams[i], reference[i]);
        bar.advance();
      }
    }
    std::vector<Config> configs;
    configs.push_back({"default", "", base});
    auto vary = [&](const std::string& knob, auto values, auto set) {
      for (auto v : values) {
        Config c{knob, fmt::format("{}", v), base};
        set(c.options, v);
        configs.push_back(c);
      }
    };
    const std::vector<float> distances =
        a.quick ? std::vector<float>{50, 150} : std::vector<float>{25, 50, 100, 150, 250, 400};
    vary("near_distance", distances, [](PipelineOptions& o, float v) { o.nearDistance = v; });
    vary("pixel_budget",
         a.quick ? std::vector<size_t>{100, 20000} : std::vector<size_t>{0, 500, 2000, 8000, 50000},
         [](PipelineOptions& o, size_t v) { o.pixelBudget = v; });
    vary("polygon_budget", std::vector<std::string>{"auto (500000)"},
         [](PipelineOptions& o, const std::string&) { o.polygonBudget = 500'000; });
    vary("cache", std::vector<std::string>{"off"},
         [](PipelineOptions& o, const std::string&) { o.cache = false; });
    vary("horizon_cell_m", a.quick ? std::vector<float>{8} : std::vector<float>{2, 4, 8, 16, 32},
         [](PipelineOptions& o, float v) { o.horizonCellSize = v; });
    vary("horizon_subsample", a.quick ? std::vector<int>{1} : std::vector<int>{1, 2, 4, 8},
         [](PipelineOptions& o, int v) { o.horizonSubsampleMoving = v; });
    vary("horizon", std::vector<std::string>{"off"},
         [](PipelineOptions& o, const std::string&) { o.horizonAllowed = false; });

    Config gc{"baseline", "geometry-all", base};
    gc.options.mode = RenderMode::GeometryAll;
    Config nc{"baseline", "near-field only", base};
    nc.options.farFieldAllowed = false;

    ProgressBar bar(
        fmt::format("{}: {} configurations x {} runs", spec, configs.size() + 3, a.repeats),
        configs.size() + 3);
    const Result raycast = runConfig(g, cams, rc, &reference, a.repeats);
    bar.advance();
    const Result geometry = runConfig(g, cams, gc, &reference, a.repeats);
    bar.advance();
    const Result nearOnly = runConfig(g, cams, nc, &reference, a.repeats);
    bar.advance();
    std::vector<Result> results;
    for (const Config& c : configs) {
      results.push_back(runConfig(g, cams, c, &reference, a.repeats));
      bar.advance();
    }
    bar.finish();

    json sceneOut = {
        {"scene", spec},
        {"frames", cams.size()},
        {"size", {size.x, size.y}},
        {"triangles", g.size()},
        {"repeats", a.repeats},
        {"baselines",
         {resultJson(raycast, raycast.frameMs, geometry.frameMs),
          resultJson(geometry, raycast.frameMs, geometry.frameMs),
          resultJson(nearOnly, raycast.frameMs, geometry.frameMs)}},
        {"table_4_1", table41(results.front().perFrame, size_t(size.x) * size_t(size.y))}};
    json rows = json::array();
    for (const Result& r : results)
      rows.push_back(resultJson(r, raycast.frameMs, geometry.frameMs));
    sceneOut["configurations"] = rows;
    out.push_back(sceneOut);
    if (!a.plotDir.empty()) writePlots(a.plotDir, spec, results, raycast, geometry, nearOnly);

    if (!a.json) {
      std::printf("\n%s: %zu triangles, %zu frames at %dx%d, medians of %d runs\n\n", spec.c_str(),
                  g.size(), cams.size(), size.x, size.y, a.repeats);
      std::printf("%-18s %-16s %10s %9s %9s %10s %11s %8s %8s %8s %8s\n", "knob", "value",
                  "frame ms", "vs ray", "vs geom", "differ %", "colour err", "polygon", "horizon",
                  "cache", "rays");
      auto row = [&](const Result& r) {
        std::printf("%-18s %-16s %10.2f %8.1fx %8.1fx %10.3f %11.5f %8zu %8zu %8zu %8zu\n",
                    r.config.knob.c_str(), r.config.value.c_str(), r.frameMs,
                    raycast.frameMs / r.frameMs, geometry.frameMs / r.frameMs, 100.0 * r.differing,
                    r.colourError, r.meanPixels.polygon, r.meanPixels.horizon, r.meanPixels.cache,
                    r.meanPixels.rayHit + r.meanPixels.rayMiss);
      };
      row(raycast);
      row(geometry);
      row(nearOnly);
      for (const Result& r : results) row(r);
      const json t = sceneOut["table_4_1"];
      std::printf("\nTable 4.1 (default pipeline), of %d pixels:\n%-26s %8s %8s %8s %10s\n",
                  size.x * size.y, "", "min %", "avg %", "max %", "avg #");
      for (const auto& [key, name] :
           std::vector<std::pair<std::string, std::string>>{{"ray_hit", "ray cast and hit"},
                                                            {"ray_miss", "ray cast and missed"},
                                                            {"cache", "taken from the cache"},
                                                            {"horizon", "culled by horizon"},
                                                            {"polygon", "covered by polygons"}})
        std::printf("%-26s %8.2f %8.2f %8.2f %10.0f\n", name.c_str(),
                    t[key]["min_pct"].get<double>(), t[key]["avg_pct"].get<double>(),
                    t[key]["max_pct"].get<double>(), t[key]["avg_count"].get<double>());
    }
  }
  if (a.json) std::printf("%s\n", out.dump(2).c_str());
  return 0;
}

}  // namespace
}  // namespace vistream

namespace vistream {

int runClientBenchTool(int argc, char** argv) {
  using namespace vistream;
  BenchArgs a;
  CLI::App app{
      "vistream-client-bench: frame time against image error for the far-field pipeline "
      "(Wimmer 2001, Figures 4.8-4.9, Table 4.1) against raycast-all and geometry-all"};
  showDefaultsInHelp(app);
  app.add_option("--scenes", a.scenes, "comma-separated scenes (files or built-in names)");
  app.add_option("--frames", a.frames, "frames of the generated walkthrough")
      ->check(atLeast<size_t>(2));
  app.add_option("--size", a.size, "image size WIDTHxHEIGHT");
  app.add_option("--repeats", a.repeats, "runs per configuration (the median is reported)")
      ->check(atLeast(1));
  app.add_option("--speed", a.speed, "relative walking speed")->check(positive());
  app.add_option("--plot-dir", a.plotDir, "write .dat files and PNG plots (gnuplot) here");
  app.add_flag("--quick", a.quick, "fewer values per knob (for tests)");
  app.add_flag("--json", a.json, "print JSON instead of tables");
  app.add_option("--log-level", a.logLevel, "trace, debug, info, warn, error, critical, off");
  app.add_flag("--shadows", a.shadows,
               "benchmark avatar self-shadowing instead (Kautz et al. 2004, Tables 1 and 2): "
               "transfer vectors of --model's first clip against Monte Carlo with Embree");
  app.add_option("--model", a.shadow.model, "--shadows: a skinned glTF model (e.g. Fox.glb)");
  app.add_option("--subdivide", a.shadow.subdivide,
                 "--shadows: split every triangle into four this many times (0..4)")
      ->check(CLI::Range(0, 4));
  app.add_option("--subdivide-by", a.shadow.subdivideBy,
                 "--shadows: 4 splits at edge midpoints, 3 around centroids (3 passes of 3 take "
                 "the Fox to 7,778 vertices, near the paper's Hand)")
      ->check(CLI::IsMember({3, 4}))
      ->default_val(4);
  app.add_option("--gloss", a.shadow.glossExponent,
                 "--shadows: the Phong exponent of the glossy rows (the paper's glossy BRDF, "
                 "against its own Monte Carlo reference; 0: no glossy rows)")
      ->check(CLI::Range(0.0f, 256.0f));
  app.add_option("--shadow-frames", a.shadow.frames, "--shadows: frames of the clip to time")
      ->check(atLeast(2));
  app.add_option("--shadow-png", a.shadow.png,
                 "--shadows: write a PNG of one pose unshadowed, shadowed by this method and by "
                 "Monte Carlo, side by side");
  app.add_option(
      "--environment", a.shadow.environment,
      "--shadows: an equirectangular HDR to light the PNG; without it, the model's own sky");
  return runFlatToolApp("vistream-client-bench", app, argc, argv, a.logLevel, [&] {
    if (!a.shadows) return runBench(a);
    a.shadow.json = a.json;
    a.shadow.quick = a.quick;
    return runShadowBench(a.shadow);
  });
}

}  // namespace vistream
