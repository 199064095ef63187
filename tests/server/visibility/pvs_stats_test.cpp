// Every field of the PVS statistics (server/visibility/epsilon_pvs.h,
// fused_pvs.h) reaches both the JSON object and the text table generated from
// their field lists (common/core/stats_output.h). The expected keys and
// values are written out here, one per member, independently of the lists;
// the static_asserts tie that count to the structs' sizes.
#include <gtest/gtest.h>

#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "common/core/stats_output.h"
#include "server/visibility/epsilon_pvs.h"
#include "server/visibility/fused_pvs.h"

namespace vistream {
namespace {

// Each member set to a value no other member has, so a row or key showing
// the wrong member is caught.
PvsStats distinctPvsStats() {
  PvsStats s;
  s.timeMs = 1.25;
  s.boxStageMs = 2.5;
  s.faceStageMs = 3.75;
  s.occluders = 104;
  s.occludersUsed = 105;
  s.linesCast = 106;
  s.lineBoxTests = 107;
  s.linePolygonTests = 108;
  s.boxes = 109;
  s.boxesOccluded = 110;
  s.boxesOccludedByFirst = 111;
  s.objectBoxes = 112;
  s.objectBoxesOccluded = 113;
  s.objectBoxesOccludedByFirst = 114;
  s.faces = 115;
  s.facesOccluded = 116;
  s.facesCulledByBoxStage = 117;
  s.facesBackFacing = 118;
  s.facesFused = 119;
  s.fusionMs = 4.5;
  s.facesPlanar = 120;
  s.facesWithoutArea = 121;
  return s;
}

// JSON key -> (table label, value as the table prints it), one per member.
const std::map<std::string, std::pair<std::string, std::string>> kPvsFields = {
    {"time_ms", {"time (ms)", "1.250"}},
    {"box_stage_ms", {"box stage (ms)", "2.500"}},
    {"face_stage_ms", {"face stage (ms)", "3.750"}},
    {"occluders", {"occluders available", "104"}},
    {"occluders_used", {"occluders used", "105"}},
    {"lines_cast", {"lines cast", "106"}},
    {"line_box_tests", {"line/box tests", "107"}},
    {"line_polygon_tests", {"line/polygon tests", "108"}},
    {"boxes", {"boxes tested", "109"}},
    {"boxes_occluded", {"boxes occluded", "110"}},
    {"boxes_occluded_by_first_occluder", {"boxes occluded by the first occluder", "111"}},
    {"object_boxes", {"object boxes tested", "112"}},
    {"object_boxes_occluded", {"object boxes occluded", "113"}},
    {"object_boxes_occluded_by_first_occluder",
     {"object boxes occluded by the first occluder", "114"}},
    {"faces_total", {"faces considered", "115"}},
    {"faces_occluded", {"faces occluded", "116"}},
    {"faces_culled_by_box_stage", {"faces culled by box stage", "117"}},
    {"faces_back_facing", {"faces facing away from the cell", "118"}},
    {"faces_fused", {"faces hidden by fused occluders", "119"}},
    {"fusion_ms", {"fusion stage (ms)", "4.500"}},
    {"faces_planar", {"faces hidden by solids fused in a plane", "120"}},
    {"faces_without_area", {"faces without area", "121"}},
};
// Four doubles and eighteen 8-byte counts: a member added to PvsStats
// without a line above fails here.
static_assert(sizeof(PvsStats) == 22 * 8);

std::vector<std::string> linesOf(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// The table row of `label`: the label, then spaces, then the value last.
bool tableHasRow(const std::vector<std::string>& lines, const std::string& label,
                 const std::string& value) {
  for (const std::string& line : lines) {
    const size_t at = line.find(label);
    if (at == std::string::npos) continue;
    const std::string rest = line.substr(at + label.size());
    if (rest.find_first_not_of(' ') == rest.size() - value.size() &&
        rest.compare(rest.size() - value.size(), value.size(), value) == 0)
      return true;
  }
  return false;
}

TEST(PvsStats, JsonHasEveryFieldUnderItsKeyWithItsValueAndType) {
  const nlohmann::json j = statsJson(distinctPvsStats());
  ASSERT_EQ(j.size(), kPvsFields.size()) << j.dump();
  for (const auto& [key, row] : kPvsFields) {
    ASSERT_TRUE(j.contains(key)) << key;
    if (key.ends_with("_ms")) {
      EXPECT_TRUE(j[key].is_number_float()) << key;
      EXPECT_EQ(fmt::format("{:.3f}", j[key].get<double>()), row.second) << key;
    } else {
      EXPECT_TRUE(j[key].is_number_unsigned()) << key;  // counts stay integers
      EXPECT_EQ(std::to_string(j[key].get<uint64_t>()), row.second) << key;
    }
  }
}

TEST(PvsStats, TableHasOneRowPerFieldWithItsLabelAndValue) {
  const std::vector<std::string> lines = linesOf(statsTable(distinctPvsStats()));
  EXPECT_EQ(lines.size(), kPvsFields.size());
  for (const auto& [key, row] : kPvsFields)
    EXPECT_TRUE(tableHasRow(lines, row.first, row.second)) << key << ": " << row.first;
}

TEST(PvsStats, TableColumnsLineUpWhateverTheLabelLength) {
  const std::vector<std::string> lines = linesOf(statsTable(distinctPvsStats(), "  "));
  ASSERT_FALSE(lines.empty());
  for (const std::string& line : lines) {
    EXPECT_EQ(line.size(), lines[0].size()) << line;  // values right-aligned in one column
    EXPECT_EQ(line.rfind("  ", 0), 0u) << line;       // the indent
  }
}

TEST(FusedPvsStats, JsonAndTableHaveEveryField) {
  FusedPvsStats s;
  s.samples = 201;
  s.erodedOccluders = 202;
  s.candidateFaces = 203;
  s.fusedCulled = 204;
  s.timeMs = 5.5;
  static_assert(sizeof(FusedPvsStats) == 5 * 8);
  const std::map<std::string, std::pair<std::string, std::string>> fields = {
      {"samples", {"samples", "201"}},
      {"eroded_occluders", {"eroded occluders", "202"}},
      {"candidate_faces", {"candidate faces", "203"}},
      {"fused_culled", {"culled by fused occluders", "204"}},
      {"time_ms", {"time (ms)", "5.500"}},
  };
  const nlohmann::json j = statsJson(s);
  EXPECT_EQ(j.size(), fields.size()) << j.dump();
  const std::vector<std::string> lines = linesOf(statsTable(s, "    "));
  EXPECT_EQ(lines.size(), fields.size());
  for (const auto& [key, row] : fields) {
    EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_TRUE(tableHasRow(lines, row.first, row.second)) << key;
  }
  EXPECT_EQ(j["fused_culled"].get<uint64_t>(), 204u);
  EXPECT_DOUBLE_EQ(j["time_ms"].get<double>(), 5.5);
}

}  // namespace
}  // namespace vistream
