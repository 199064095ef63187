#include "client/app/walkthrough.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdlib>
#include <map>
#include <stdexcept>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/core/median.h"
#include "common/core/parse.h"

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
  const WidthHeight size = parseWidthHeight(text, option, 16, 8192);
  return {size.width, size.height};
}

ImageDifference compareImages(const ImageRgb8& a, const ImageRgb8& b, int tolerance) {
  VS_CHECK_EQ(a.width, b.width);  // the caller's contract: images of one camera
  VS_CHECK_EQ(a.height, b.height);
  ImageDifference d;
  const size_t n = size_t(a.width) * size_t(a.height);
  size_t differing = 0;
  double sum = 0.0;
  for (size_t p = 0; p < n; ++p) {
    int e = 0, worst = 0;
    for (int c = 0; c < 3; ++c) {
      const int diff =
          std::abs(int(a.pixels[3 * p + size_t(c)]) - int(b.pixels[3 * p + size_t(c)]));
      e += diff;
      worst = std::max(worst, diff);
    }
    differing += worst > tolerance;
    sum += double(e) / (3.0 * 255.0);
  }
  for (int y = 1; y + 1 < b.height; ++y)
    for (int x = 1; x + 1 < b.width; ++x) {
      const glm::ivec3 gap = glm::abs(glm::ivec3(a.at(x, y)) - glm::ivec3(b.at(x, y)));
      if (std::max({gap.x, gap.y, gap.z}) <= tolerance) continue;
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

// Sums over the frames; means are sums / frames (1 for no frames).
struct Means {
  PixelCounts pixelSums;
  StageTimes msSums;
  double frames = 1.0;
  double intakeMs = 0, wallMs = 0;  // sums
  double differing = 0, colourError = 0;
  size_t compared = 0;

  // f(field, mean) for every pixel class, in PixelCounts' list order.
  template <class F>
  void forEachPixelMean(F&& f) const {
    pixelSums.forEachField(
        [&](const StatField& field, size_t sum) { f(field, double(sum) / frames); });
  }
  template <class F>
  void forEachStageMean(F&& f) const {
    msSums.forEachField([&](const StatField& field, double sum) { f(field, sum / frames); });
  }
  double frameMs() const { return msSums.total / frames; }
};

Means means(const std::vector<FrameRecord>& frames) {
  Means m;
  for (const FrameRecord& f : frames) {
    m.pixelSums += f.report.pixels;
    m.msSums += f.report.ms;
    m.intakeMs += f.geometryIntakeMs;
    m.wallMs += f.wallMs;
    if (f.compared) {
      ++m.compared;
      m.differing += f.difference.differingFraction;
      m.colourError += f.difference.meanColourError;
    }
  }
  m.frames = frames.empty() ? 1.0 : double(frames.size());
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
  size_t farRan = 0, horizonRan = 0, cacheRan = 0, avatarsRan = 0, impostorsRan = 0;
  for (const FrameRecord& f : frames) {
    nlohmann::json j = f.report.toJson();
    j["frame"] = f.frame;
    j["t"] = f.t;
    j["frame_ms"] = f.report.ms.total;
    j["geometry_intake_ms"] = f.geometryIntakeMs;
    j["wall_ms"] = f.wallMs;
    if (f.compared)
      j["error"] = {{"differing_fraction", f.difference.differingFraction},
                    {"mean_colour_error", f.difference.meanColourError}};
    if (f.contrast) {
      j["distinct_colours"] = f.contrast->distinctColours;
      j["luminance_std"] = f.contrast->luminanceStd;
    }
    if (f.avatars) {
      const AvatarFrame& a = *f.avatars;
      j["avatars"] = {{"in_view", a.inView},
                      {"beyond_d", a.beyond},
                      {"outside_view", a.outside},
                      {"poses_shaded", a.posesShaded},
                      {"poses_reused", a.posesReused},
                      {"vertices_shaded", a.verticesShaded},
                      {"ms", a.ms},
                      {"pixels", f.avatarPixels},
                      {"why", a.why}};
      ++why["avatars"][a.why];
      avatarsRan += a.inView > 0;
    }
    perFrame.push_back(std::move(j));
    ++why["far_field"][f.report.farFieldWhy];
    ++why["horizon_tracing"][f.report.horizonWhy];
    ++why["image_cache"][f.report.cacheWhy];
    ++why["impostors"][f.report.impostorsWhy];
    impostorsRan += f.report.impostorsRan;
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
                                    : stage == "avatars"         ? avatarsRan
                                    : stage == "impostors"       ? impostorsRan
                                                                 : cacheRan},
                     {"reasons", r}};
  }
  nlohmann::json pixels = nlohmann::json::object(), stageMs = nlohmann::json::object();
  m.forEachPixelMean([&](const StatField& f, double v) { pixels[std::string(f.key)] = v; });
  m.forEachStageMean([&](const StatField& f, double v) { stageMs[std::string(f.key)] = v; });
  nlohmann::json out = {
      {"frames", frames.size()},
      {"mean_frame_ms", m.frameMs()},
      {"geometry_intake_ms_total", m.intakeMs},
      {"geometry_intake_ms_per_frame", m.intakeMs / m.frames},
      {"wall_ms_per_frame", m.wallMs / m.frames},
      {"pixels", pixels},
      {"mean_stage_ms", stageMs},
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
  std::vector<double> colours, spread;
  for (const FrameRecord& f : frames)
    if (f.contrast) {
      colours.push_back(double(f.contrast->distinctColours));
      spread.push_back(f.contrast->luminanceStd);
    }
  if (!colours.empty()) {
    out["contrast"] = {{"min_distinct_colours", *std::min_element(colours.begin(), colours.end())},
                       {"median_distinct_colours", median(colours)},
                       {"min_luminance_std", *std::min_element(spread.begin(), spread.end())},
                       {"median_luminance_std", median(spread)}};
  }
  if (m.compared)
    out["error"] = {{"frames_compared", m.compared},
                    {"mean_differing_fraction", m.differing},
                    {"mean_colour_error", m.colourError}};
  return out;
}

std::string walkthroughTable(const std::vector<FrameRecord>& frames, const PipelineOptions& o) {
  const Means m = means(frames);
  double total = 0;
  m.forEachPixelMean([&](const StatField&, double v) { total += v; });
  auto pct = [&](double v) { return total > 0 ? 100.0 * v / total : 0.0; };
  std::string s = fmt::format("mode {}, {} frames, mean frame {:.2f} ms\n\n",
                              renderModeName(o.mode), frames.size(), m.frameMs());
  s += fmt::format("{:<28} {:>12} {:>8}\n", "pixels (mean a frame)", "count", "share");
  m.forEachPixelMean([&](const StatField& f, double v) {
    s += fmt::format("{:<28} {:>12.0f} {:>7.2f}%\n", f.label, v, pct(v));
  });
  s += fmt::format("\n{:<28} {:>12}\n", "stage (mean)", "ms");
  m.forEachStageMean(
      [&](const StatField& f, double v) { s += fmt::format("{:<28} {:>12.3f}\n", f.label, v); });
  s += fmt::format("{:<28} {:>12.3f}\n", "geometry intake", m.intakeMs / m.frames);
  s += fmt::format("{:<28} {:>12.3f}\n", "wall clock (intake + frame)", m.wallMs / m.frames);
  s += fmt::format("geometry intake: {:.1f} ms in total\n", m.intakeMs);
  std::vector<double> avatarMs;
  for (const FrameRecord& f : frames)
    if (f.avatars) avatarMs.push_back(f.avatars->ms);
  if (!avatarMs.empty())
    s += fmt::format("avatars (select, pose, shadow, build): median {:.2f} ms a frame\n",
                     median(avatarMs));
  if (m.compared)
    s += fmt::format("\nagainst raycast-all: {:.3f}% of pixels differ, mean colour error {:.5f}\n",
                     100.0 * m.differing, m.colourError);
  // Which stages ran, and why (the most common reason).
  std::map<std::string, std::map<std::string, size_t>> why;
  for (const FrameRecord& f : frames) {
    ++why["far field"][(f.report.farFieldRan ? "ran: " : "off: ") + f.report.farFieldWhy];
    ++why["horizon tracing"][(f.report.horizonRan ? "ran: " : "off: ") + f.report.horizonWhy];
    ++why["image cache"][(f.report.cacheRan ? "ran: " : "off: ") + f.report.cacheWhy];
    ++why["impostors"][(f.report.impostorsRan ? "ran: " : "off: ") + f.report.impostorsWhy];
    if (f.avatars) ++why["avatars"][(f.avatars->inView ? "ran: " : "off: ") + f.avatars->why];
  }
  s += "\n";
  for (const auto& [stage, reasons] : why)
    for (const auto& [text, count] : reasons)
      s += fmt::format("{:<16} {:>6} frames  {}\n", stage, count, text);
  return s;
}

}  // namespace vistream
