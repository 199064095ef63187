#include "client/app/walkthrough.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdlib>
#include <map>
#include <stdexcept>

#include "common/core/error.h"

namespace vistream {

std::vector<Camera> camerasFromPath(const std::vector<PathSample>& path, const glm::dvec3& origin,
                                    int width, int height, float vfovDeg) {
  std::vector<Camera> out;
  out.reserve(path.size());
  for (const PathSample& s : path) {
    Camera c;
    c.eye = glm::vec3(s.position - origin);
    c.yawDeg = float(s.yawDeg);
    c.pitchDeg = float(std::clamp(s.pitchDeg, -89.0, 89.0));
    c.width = width;
    c.height = height;
    c.vfovDeg = vfovDeg;
    out.push_back(c);
  }
  return out;
}

glm::ivec2 parseImageSize(const std::string& text, const char* option) {
  const size_t x = text.find('x');
  int w = 0, h = 0;
  try {
    size_t used = 0;
    if (x == std::string::npos) throw std::invalid_argument("no x");
    w = std::stoi(text.substr(0, x), &used);
    if (used != x) throw std::invalid_argument("width");
    h = std::stoi(text.substr(x + 1), &used);
    if (used != text.size() - x - 1) throw std::invalid_argument("height");
  } catch (const std::exception&) {
    throwInputError("{} {}: expected WIDTHxHEIGHT, e.g. 640x480", option, text);
  }
  if (w < 16 || h < 16 || w > 8192 || h > 8192)
    throwInputError("{} {}: each side must lie in [16, 8192] pixels", option, text);
  return {w, h};
}

ImageDifference compareImages(const ImageRgb8& a, const ImageRgb8& b) {
  if (a.width != b.width || a.height != b.height)
    throw std::logic_error("compareImages: sizes differ");
  ImageDifference d;
  const size_t n = size_t(a.width) * size_t(a.height);
  size_t differing = 0;
  double sum = 0.0;
  for (size_t p = 0; p < n; ++p) {
    int e = 0;
    for (int c = 0; c < 3; ++c)
      e += std::abs(int(a.pixels[3 * p + size_t(c)]) - int(b.pixels[3 * p + size_t(c)]));
    differing += e > 0;
    sum += double(e) / (3.0 * 255.0);
  }
  for (int y = 1; y + 1 < b.height; ++y)
    for (int x = 1; x + 1 < b.width; ++x) {
      if (a.at(x, y) == b.at(x, y)) continue;
      bool uniform = true;
      for (int dy = -1; dy <= 1 && uniform; ++dy)
        for (int dx = -1; dx <= 1; ++dx) uniform = uniform && b.at(x + dx, y + dy) == b.at(x, y);
      d.interiorDiffering += uniform;
    }
  d.differingFraction = n ? double(differing) / double(n) : 0.0;
  d.meanColourError = n ? sum / double(n) : 0.0;
  return d;
}

namespace {

struct Means {
  double polygon = 0, horizon = 0, cache = 0, rayHit = 0, rayMiss = 0, background = 0, frameMs = 0;
  StageTimes ms;
  double differing = 0, colourError = 0;
  size_t compared = 0;
};

Means means(const std::vector<FrameRecord>& frames) {
  Means m;
  PixelCounts p;
  for (const FrameRecord& f : frames) {
    p += f.report.pixels;
    m.ms += f.report.ms;
    if (f.compared) {
      ++m.compared;
      m.differing += f.difference.differingFraction;
      m.colourError += f.difference.meanColourError;
    }
  }
  m.polygon = double(p.polygon);
  m.horizon = double(p.horizon);
  m.cache = double(p.cache);
  m.rayHit = double(p.rayHit);
  m.rayMiss = double(p.rayMiss);
  m.background = double(p.background);
  const double n = frames.empty() ? 1.0 : double(frames.size());
  for (double* v : {&m.polygon, &m.horizon, &m.cache, &m.rayHit, &m.rayMiss, &m.background,
                    &m.ms.nearSelect, &m.ms.nearDraw, &m.ms.opacity, &m.ms.horizon, &m.ms.cache,
                    &m.ms.raycast, &m.ms.compose, &m.ms.total})
    *v /= n;
  if (m.compared) {
    m.differing /= double(m.compared);
    m.colourError /= double(m.compared);
  }
  return m;
}

}  // namespace

nlohmann::json walkthroughJson(const std::vector<FrameRecord>& frames, const PipelineOptions& o,
                               int width, int height) {
  const Means m = means(frames);
  nlohmann::json perFrame = nlohmann::json::array();
  std::map<std::string, std::map<std::string, size_t>> why;  // stage -> reason -> frames
  size_t farRan = 0, horizonRan = 0, cacheRan = 0;
  for (const FrameRecord& f : frames) {
    nlohmann::json j = f.report.toJson();
    j["frame"] = f.frame;
    j["t"] = f.t;
    j["frame_ms"] = f.report.ms.total;
    if (f.compared)
      j["error"] = {{"differing_fraction", f.difference.differingFraction},
                    {"mean_colour_error", f.difference.meanColourError}};
    perFrame.push_back(std::move(j));
    ++why["far_field"][f.report.farFieldWhy];
    ++why["horizon_tracing"][f.report.horizonWhy];
    ++why["image_cache"][f.report.cacheWhy];
    farRan += f.report.farFieldRan;
    horizonRan += f.report.horizonRan;
    cacheRan += f.report.cacheRan;
  }
  nlohmann::json stages;
  for (const auto& [stage, reasons] : why) {
    nlohmann::json r = nlohmann::json::object();
    for (const auto& [text, count] : reasons) r[text.empty() ? "-" : text] = count;
    stages[stage] = {{"frames_ran", stage == "far_field"         ? farRan
                                    : stage == "horizon_tracing" ? horizonRan
                                                                 : cacheRan},
                     {"reasons", r}};
  }
  nlohmann::json out = {
      {"frames", frames.size()},
      {"mean_frame_ms", m.ms.total},
      {"pixels",
       {{"polygon", m.polygon},
        {"horizon", m.horizon},
        {"cache", m.cache},
        {"ray_hit", m.rayHit},
        {"ray_miss", m.rayMiss},
        {"background", m.background}}},
      {"mean_stage_ms",
       {{"near_select", m.ms.nearSelect},
        {"near_draw", m.ms.nearDraw},
        {"opacity", m.ms.opacity},
        {"horizon", m.ms.horizon},
        {"cache", m.ms.cache},
        {"raycast", m.ms.raycast},
        {"compose", m.ms.compose}}},
      {"mode", renderModeName(o.mode)},
      {"size", {width, height}},
      {"options",
       {{"near_distance", o.nearDistance},
        {"pixel_budget", o.pixelBudget},
        {"polygon_budget", o.polygonBudget},
        {"cache", o.cache},
        {"max_stale_pixels", o.maxStalePixels},
        {"horizon_cell_size", o.horizonCellSize},
        {"horizon_subsample_moving", o.horizonSubsampleMoving}}},
      {"stages", stages},
      {"per_frame", perFrame},
  };
  if (m.compared)
    out["error"] = {{"frames_compared", m.compared},
                    {"mean_differing_fraction", m.differing},
                    {"mean_colour_error", m.colourError}};
  return out;
}

std::string walkthroughTable(const std::vector<FrameRecord>& frames, const PipelineOptions& o) {
  const Means m = means(frames);
  const double total = m.polygon + m.horizon + m.cache + m.rayHit + m.rayMiss + m.background;
  auto pct = [&](double v) { return total > 0 ? 100.0 * v / total : 0.0; };
  std::string s = fmt::format("mode {}, {} frames, mean frame {:.2f} ms\n\n",
                              renderModeName(o.mode), frames.size(), m.ms.total);
  s += fmt::format("{:<28} {:>12} {:>8}\n", "pixels (mean a frame)", "count", "share");
  const std::pair<const char*, double> rows[] = {
      {"covered by polygons", m.polygon}, {"culled by horizon", m.horizon},
      {"taken from the cache", m.cache},  {"ray cast and hit", m.rayHit},
      {"ray cast and missed", m.rayMiss}, {"background (no far field)", m.background}};
  for (const auto& [name, v] : rows)
    s += fmt::format("{:<28} {:>12.0f} {:>7.2f}%\n", name, v, pct(v));
  s += fmt::format("\n{:<28} {:>12}\n", "stage (mean)", "ms");
  const std::pair<const char*, double> stages[] = {{"near-field selection", m.ms.nearSelect},
                                                   {"near-field drawing", m.ms.nearDraw},
                                                   {"opacity buffer", m.ms.opacity},
                                                   {"horizon tracing", m.ms.horizon},
                                                   {"cache planning", m.ms.cache},
                                                   {"ray casting", m.ms.raycast},
                                                   {"composition", m.ms.compose},
                                                   {"frame", m.ms.total}};
  for (const auto& [name, v] : stages) s += fmt::format("{:<28} {:>12.3f}\n", name, v);
  if (m.compared)
    s += fmt::format("\nagainst raycast-all: {:.3f}% of pixels differ, mean colour error {:.5f}\n",
                     100.0 * m.differing, m.colourError);
  // Which stages ran, and why (the most common reason).
  std::map<std::string, std::map<std::string, size_t>> why;
  for (const FrameRecord& f : frames) {
    ++why["far field"][(f.report.farFieldRan ? "ran: " : "off: ") + f.report.farFieldWhy];
    ++why["horizon tracing"][(f.report.horizonRan ? "ran: " : "off: ") + f.report.horizonWhy];
    ++why["image cache"][(f.report.cacheRan ? "ran: " : "off: ") + f.report.cacheWhy];
  }
  s += "\n";
  for (const auto& [stage, reasons] : why)
    for (const auto& [text, count] : reasons)
      s += fmt::format("{:<16} {:>6} frames  {}\n", stage, count, text);
  return s;
}

}  // namespace vistream
