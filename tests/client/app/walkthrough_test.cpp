// Every field of the frame statistics (PixelCounts, StageTimes in
// client/farfield/pipeline.h) reaches the per-frame JSON, the walkthrough's
// JSON summary and its table (client/app/walkthrough.h), with the right
// value. The expected keys and labels are written out here, one per member,
// independently of the field lists; the static_asserts tie that count to the
// structs' sizes.
#include "client/app/walkthrough.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <map>
#include <string>
#include <utility>
#include <vector>

namespace vistream {
namespace {

static_assert(sizeof(PixelCounts) == 7 * sizeof(size_t));
static_assert(sizeof(StageTimes) == 10 * sizeof(double));

// JSON key -> table label.
const std::map<std::string, std::string> kPixelFields = {
    {"polygon", "covered by polygons"},   {"horizon", "culled by horizon"},
    {"cache", "taken from the cache"},    {"ray_hit", "ray cast and hit"},
    {"ray_miss", "ray cast and missed"},  {"background", "background (no far field)"},
    {"impostor", "drawn from impostors"},
};
const std::map<std::string, std::string> kStageFields = {
    {"near_select", "near-field selection"},
    {"near_draw", "near-field drawing"},
    {"shade", "colour lookups"},
    {"opacity", "opacity buffer"},
    {"horizon", "horizon tracing"},
    {"cache", "cache planning"},
    {"raycast", "ray casting"},
    {"compose", "composition"},
    {"impostors", "impostor splatting"},
    {"total", "frame"},
};

// A frame whose every counter differs from every other: pixels k * 100 +
// 10 * i for the i-th class, stage times k plus a fraction of a ms that
// differs between stages.
FrameRecord frame(size_t k) {
  FrameRecord f;
  f.frame = k;
  PixelCounts& p = f.report.pixels;
  p.polygon = k * 100 + 10;
  p.horizon = k * 100 + 20;
  p.cache = k * 100 + 30;
  p.rayHit = k * 100 + 40;
  p.rayMiss = k * 100 + 50;
  p.background = k * 100 + 60;
  p.impostor = k * 100 + 70;
  StageTimes& t = f.report.ms;
  const double base = double(k);
  t.nearSelect = base + 0.125;
  t.nearDraw = base + 0.25;
  t.shade = base + 0.3125;
  t.opacity = base + 0.375;
  t.horizon = base + 0.5;
  t.cache = base + 0.625;
  t.raycast = base + 0.75;
  t.compose = base + 0.875;
  t.impostors = base + 0.9375;
  t.total = base + 1.0;
  return f;
}

// Values of frame(k) by JSON key, written out again.
std::map<std::string, double> pixelValues(double k) {
  return {{"polygon", k * 100 + 10}, {"horizon", k * 100 + 20},  {"cache", k * 100 + 30},
          {"ray_hit", k * 100 + 40}, {"ray_miss", k * 100 + 50}, {"background", k * 100 + 60},
          {"impostor", k * 100 + 70}};
}
std::map<std::string, double> stageValues(double k) {
  return {{"near_select", k + 0.125}, {"near_draw", k + 0.25}, {"shade", k + 0.3125},
          {"opacity", k + 0.375},     {"horizon", k + 0.5},    {"cache", k + 0.625},
          {"raycast", k + 0.75},      {"compose", k + 0.875},  {"impostors", k + 0.9375},
          {"total", k + 1.0}};
}

TEST(FrameReport, JsonHasEveryPixelClassAndStageTimeUnderItsKey) {
  const nlohmann::json j = frame(3).report.toJson();
  ASSERT_EQ(j["pixels"].size(), kPixelFields.size()) << j["pixels"].dump();
  for (const auto& [key, value] : pixelValues(3)) EXPECT_EQ(j["pixels"][key].get<double>(), value);
  ASSERT_EQ(j["ms"].size(), kStageFields.size()) << j["ms"].dump();
  for (const auto& [key, value] : stageValues(3)) EXPECT_EQ(j["ms"][key].get<double>(), value);
}

TEST(Walkthrough, JsonSummaryHasTheMeanOfEveryPixelClassAndStage) {
  // Frames 1 and 3: every mean is the value of a frame 2.
  const std::vector<FrameRecord> frames = {frame(1), frame(3)};
  const nlohmann::json j = walkthroughJson(frames, PipelineOptions{}, 64, 48);
  ASSERT_EQ(j["pixels"].size(), kPixelFields.size()) << j["pixels"].dump();
  for (const auto& [key, value] : pixelValues(2)) EXPECT_EQ(j["pixels"][key].get<double>(), value);
  ASSERT_EQ(j["mean_stage_ms"].size(), kStageFields.size()) << j["mean_stage_ms"].dump();
  for (const auto& [key, value] : stageValues(2))
    EXPECT_EQ(j["mean_stage_ms"][key].get<double>(), value) << key;
  EXPECT_EQ(j["mean_frame_ms"].get<double>(), 3.0);
}

TEST(Walkthrough, TableHasARowForEveryPixelClassAndStageWithItsMean) {
  const std::vector<FrameRecord> frames = {frame(1), frame(3)};
  const std::string table = walkthroughTable(frames, PipelineOptions{});
  const std::map<std::string, double> pixels = pixelValues(2), stages = stageValues(2);
  double total = 0;
  for (const auto& [key, value] : pixels) total += value;
  for (const auto& [key, label] : kPixelFields) {
    const double v = pixels.at(key);
    const std::string row = fmt::format("{:<28} {:>12.0f} {:>7.2f}%\n", label, v, 100 * v / total);
    EXPECT_NE(table.find(row), std::string::npos) << "missing row: " << row << table;
  }
  for (const auto& [key, label] : kStageFields) {
    const std::string row = fmt::format("{:<28} {:>12.3f}\n", label, stages.at(key));
    EXPECT_NE(table.find(row), std::string::npos) << "missing row: " << row << table;
  }
}

// Geometry intake and wall-clock time: frame k took up geometry for 2k ms
// and spent 3k ms in all.
TEST(Walkthrough, ReportsGeometryIntakeAndWallClockPerFrameAndInTotal) {
  std::vector<FrameRecord> frames = {frame(1), frame(3)};
  for (FrameRecord& f : frames) {
    f.geometryIntakeMs = 2.0 * double(f.frame);
    f.wallMs = 3.0 * double(f.frame);
  }
  const nlohmann::json j = walkthroughJson(frames, PipelineOptions{}, 64, 48);
  EXPECT_EQ(j["geometry_intake_ms_total"].get<double>(), 8.0);
  EXPECT_EQ(j["geometry_intake_ms_per_frame"].get<double>(), 4.0);
  EXPECT_EQ(j["wall_ms_per_frame"].get<double>(), 6.0);
  ASSERT_EQ(j["per_frame"].size(), 2u);
  EXPECT_EQ(j["per_frame"][1]["geometry_intake_ms"].get<double>(), 6.0);
  EXPECT_EQ(j["per_frame"][1]["wall_ms"].get<double>(), 9.0);
  const std::string table = walkthroughTable(frames, PipelineOptions{});
  for (const std::string& row :
       {fmt::format("{:<28} {:>12.3f}\n", "geometry intake", 4.0),
        fmt::format("{:<28} {:>12.3f}\n", "wall clock (intake + frame)", 6.0),
        std::string("geometry intake: 8.0 ms in total\n")})
    EXPECT_NE(table.find(row), std::string::npos) << "missing row: " << row << table;
}

}  // namespace
}  // namespace vistream
