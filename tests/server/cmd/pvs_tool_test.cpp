// End-to-end tests of the vistream-pvs executable: the command-line and JSON
// contracts of cell, bake, query, merge, walk and bench.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "tests/common/support/box_scenes.h"
#include "tests/common/support/run_tool.h"
#include "tests/common/support/temp_dir.h"
#include "tests/common/support/tool_checks.h"

namespace {

namespace fs = std::filesystem;

using vistream::testing::ToolRun;

const vistream::testing::Tool runPvs{"vistream-pvs"};

// Ground, a wall and a box hidden behind it. Face IDs: 0 ground; wall 1..6
// (-x,+x,-y,+y,-z,+z); hidden box 7..12.
std::string wallScene() {
  vistream::testing::GroundAndBoxesObj o(-50, -50, 50, 50);
  o.box("wall", -10, -5, 10, -4.83, 10.3);  // x0, z0, x1, z1, height
  o.box("hidden", -1, -10, 1, -8, 2);
  return o.obj;
}

TEST(PvsTool, CellPrintsTheContractedJsonAndCullsTheHiddenBox) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const ToolRun r =
      runPvs("cell --scene " + scene.string() + " --cell -1,1,0,1,2,2 --json --method paper");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["stats"]["method"], "paper");
  const auto faces = j["faces"].get<std::vector<uint32_t>>();
  EXPECT_TRUE(std::is_sorted(faces.begin(), faces.end()));
  for (uint32_t hidden = 7; hidden <= 12; ++hidden)
    EXPECT_FALSE(std::binary_search(faces.begin(), faces.end(), hidden));
  EXPECT_TRUE(std::binary_search(faces.begin(), faces.end(), 6u));  // the wall's front face
  EXPECT_EQ(j["objects"].get<std::vector<std::string>>(),
            (std::vector<std::string>{"ground", "wall"}));
  for (const char* key : {"time_ms", "occluders_used", "lines_cast", "line_box_tests",
                          "line_polygon_tests", "faces_culled_by_box_stage"})
    EXPECT_TRUE(j["stats"].contains(key)) << key;
  // Accelerations switched off give the same PVS; the fused stages (the
  // default auto picks the horizons over the wall's solid columns) only
  // remove faces, never the wall's front or the ground.
  for (const char* flags :
       {"--method paper --no-bbox", "--method paper --no-incremental",
        "--method paper --no-redundant-occluders", "--method paper --no-redundant-rays",
        "--method fused --epsilon 0.5", "--method horizons", ""}) {
    const ToolRun other =
        runPvs("cell --scene " + scene.string() + " --cell -1,1,0,1,2,2 --json " + flags);
    ASSERT_EQ(other.status, 0) << flags << other.err;
    const auto of = nlohmann::json::parse(other.out)["faces"].get<std::vector<uint32_t>>();
    EXPECT_TRUE(std::includes(faces.begin(), faces.end(), of.begin(), of.end()) || of == faces)
        << flags;
    for (uint32_t f : {0u, 6u}) EXPECT_TRUE(std::binary_search(of.begin(), of.end(), f)) << flags;
  }
}

TEST(PvsTool, CellWithGroundTruthSaysWhatTheCellSeesAndWhichPvsFacesItDoesNot) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const std::string args = "cell --scene " + scene.string() +
                           " --cell -1,1,0,1,2,2 --method paper --ground-truth --gt-points 8 "
                           "--gt-res 64";
  const ToolRun r = runPvs(args + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const auto faces = j["faces"].get<std::vector<uint32_t>>();
  const auto& g = j["ground_truth"];
  // From in front of the wall only the ground and the wall's front face
  // (+z, face 6) can be seen.
  EXPECT_EQ(g["seen_faces"], 2);
  EXPECT_TRUE(g["missing_faces"].empty());
  EXPECT_DOUBLE_EQ(g["pvs_over_seen"].get<double>(), double(faces.size()) / 2.0);
  std::vector<uint32_t> unseen;
  for (uint32_t f : faces)
    if (f != 0 && f != 6) unseen.push_back(f);
  EXPECT_EQ(g["unseen_face_ids"].get<std::vector<uint32_t>>(), unseen);
  EXPECT_EQ(g["unseen_faces"], unseen.size());
  size_t byDistance = 0;
  for (const auto& band : g["unseen_by_distance"]) byDistance += band["faces"].get<size_t>();
  EXPECT_EQ(byDistance, unseen.size());
  const auto& facing = g["unseen_facing"];
  EXPECT_EQ(
      facing["up"].get<size_t>() + facing["side"].get<size_t>() + facing["down"].get<size_t>(),
      unseen.size());
  // The wall's top (face 4) and bottom (3) face up and down; its sides
  // and back (1, 2, 5) sideways; all of the wall is within 25 m.
  const auto has = [&](uint32_t f) { return std::binary_search(unseen.begin(), unseen.end(), f); };
  EXPECT_EQ(facing["up"].get<size_t>(), size_t(has(4)));
  EXPECT_EQ(facing["down"].get<size_t>(), size_t(has(3)));
  EXPECT_EQ(facing["side"].get<size_t>(), size_t(has(1)) + has(2) + has(5));
  EXPECT_EQ(g["unseen_by_distance"][0]["faces"].get<size_t>(), unseen.size());
  EXPECT_GT(g["viewpoints"].get<size_t>(), 0u);
  // The table says the same to a person.
  const ToolRun table = runPvs(args);
  ASSERT_EQ(table.status, 0) << table.err;
  EXPECT_NE(table.out.find("faces seen"), std::string::npos) << table.out;
  EXPECT_NE(table.out.find("missing (seen, not in the PVS)"), std::string::npos) << table.out;
}

TEST(PvsTool, BakesQueriesAndMergesAndRejectsACorruptDatabase) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const std::string db = (dir / "w.db").string();
  ToolRun r =
      runPvs("bake --scene " + scene.string() + " --cell-size 4,2,4 --out " + db + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_GT(nlohmann::json::parse(r.out)["computed_cells"].get<int>(), 10);
  r = runPvs("query --db " + db + " --point 0,1.5,1 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto q = nlohmann::json::parse(r.out);
  EXPECT_EQ(q["cell"].size(), 3u);
  const auto faces = q["faces"].get<std::vector<uint32_t>>();
  EXPECT_TRUE(std::binary_search(faces.begin(), faces.end(), 6u));
  for (int shard = 0; shard < 2; ++shard)
    ASSERT_EQ(runPvs("bake --scene " + scene.string() + " --cell-size 4,2,4 --shard " +
                     std::to_string(shard) + "/2 --out " +
                     (dir / ("s" + std::to_string(shard) + ".db")).string())
                  .status,
              0);
  r = runPvs("merge " + (dir / "s0.db").string() + " " + (dir / "s1.db").string() + " --out " +
             (dir / "m.db").string());
  ASSERT_EQ(r.status, 0) << r.err;
  r = runPvs("query --db " + (dir / "m.db").string() + " --point 0,1.5,1 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["faces"].get<std::vector<uint32_t>>(), faces);

  { std::ofstream(dir / "bad.db") << "not a database at all, just some text that is long enough"; }
  r = runPvs("query --db " + (dir / "bad.db").string() + " --cell 0,0,0");
  vistream::testing::expectFailedSaying(r, 1, "bad.db");
  r = runPvs("query --db " + db + " --point 1,2");
  vistream::testing::expectFailedSaying(r, 1, "--point");
  r = runPvs("bake --scene " + scene.string() + " --cell-size 0 --out " + (dir / "z.db").string());
  vistream::testing::expectFailedSaying(r, 1, "--cell-size");
  r = runPvs("bake --scene " + scene.string() + " --cell-size 4 --fusion maybe --out " +
             (dir / "z.db").string());
  vistream::testing::expectFailedSaying(r, 1, "--fusion");
}

TEST(PvsTool, BakeNamesTheFusedStageInTheDatabasesMethod) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  for (const std::string fusion : {"none", "horizons"}) {
    const std::string db = (dir / (fusion + ".db")).string();
    ASSERT_EQ(runPvs("bake --scene " + scene.string() + " --cell-size 4,2,4 --fusion " + fusion +
                     " --out " + db)
                  .status,
              0);
    const ToolRun info = runPvs("query --db " + db + " --point 0,1.5,1 --json");
    ASSERT_EQ(info.status, 0) << info.err;
    EXPECT_EQ(nlohmann::json::parse(info.out)["method"],
              fusion == "none" ? "paper+back-faces+planar" : "paper+back-faces+planar+horizons");
  }
}

TEST(PvsTool, WalkPrintsTheSummaryAndOneRecordPerFrame) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const fs::path path = dir.write(
      "p.csv",
      "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,2,0,0\n0.033,0,1.7,1.95,10,0\n0.066,0,1.7,1.9,180,0\n");
  for (const char* method : {"A", "B", "C", "D", "adaptive"}) {
    const ToolRun r = runPvs("walk --scene " + scene.string() + " --path " + path.string() +
                             " --method " + method + " --json --with-faces");
    ASSERT_EQ(r.status, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    for (const char* key :
         {"node_tests_mean", "culling_ms_mean", "frame_ms_mean", "visible_faces_mean"})
      EXPECT_TRUE(j["summary"].contains(key)) << key;
    ASSERT_EQ(j["frames"].size(), 3u);
    for (const auto& f : j["frames"]) {
      for (const char* key : {"node_tests", "culling_ms", "visible_faces", "faces"})
        EXPECT_TRUE(f.contains(key)) << key;
      EXPECT_EQ(f["faces"].size(), f["visible_faces"].get<size_t>());
    }
  }
  const ToolRun bad =
      runPvs("walk --scene " + scene.string() + " --path " + path.string() + " --method Q");
  vistream::testing::expectFailedSaying(bad, 1, "--method");
  const ToolRun badP = runPvs("walk --scene " + scene.string() + " --path " + path.string() +
                              " --method C --p-vp 1.5");
  vistream::testing::expectFailedSaying(badP, 1, "--p-vp");
}

TEST(PvsTool, OutOfRangeNumbersAndBadBoxesFailBeforeTheSceneLoadsNamingTheOption) {
  using vistream::testing::expectEachOptionNamed;
  const std::string missing = "/nonexistent/scene.obj";
  vistream::testing::RefusedCommand pvs{
      .tool = "vistream-pvs", .common = "cell --scene " + missing, .unopened = missing};
  expectEachOptionNamed(pvs, {"--cell 1,2,3"});
  pvs.common = "cell --scene " + missing + " --cell 0,0,0,1,1,1";
  expectEachOptionNamed(pvs, {"--fused-res 1", "--epsilon -1", "--large-occluders -2"});
  pvs.common = "bake --scene " + missing + " --cell-size 4 --out /tmp/never.db";
  expectEachOptionNamed(pvs, {"--threads -1", "--region 1,2,3", "--region 5,0,0,1,1,1"});
  pvs.common = "walk --scene " + missing + " --path p.csv";
  expectEachOptionNamed(pvs, {"--p-skip 2", "--fov 180", "--occluders 0"});
  pvs.common = "walk-bench";
  expectEachOptionNamed(pvs, {"--frames 0"});
  pvs.common = "bench";
  expectEachOptionNamed(pvs, {"--district -1", "--bake-cell 0", "--gt-probes -1"});
}

// A street cell at the origin and, 120-170 m ahead (-z, a little to +x), a
// row of boxes: a far field beyond d = 100 m in one sector (azimuth -83 to
// -66 degrees) and band.
std::string farRowScene() {
  vistream::testing::GroundAndBoxesObj o(-300, -300, 300, 300);
  for (int k = 0; k < 8; ++k)
    o.box("far" + std::to_string(k), 15 + 5 * k, -170 + 3 * (k % 3), 19 + 5 * k, -120,
          8 + 3 * (k % 4));
  return o.obj;
}

TEST(PvsTool, ImpostorsPrintTheContractedJsonForEachImpostorOfTheCell) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("row.obj", farRowScene());
  const std::string common = "impostors --scene " + scene.string() +
                             " --cell -2,1,-2,2,3,2 --near-distance 100 "
                             "--lighting-cache none --max-rays 8 --pixel-filter 0 ";
  // The thesis's placement: every site heavy enough gets its impostor.
  const ToolRun r = runPvs(common + "--json --min-triangles 20 --max-bytes-ratio 0");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["impostors"].size(), 1u) << r.out;
  const auto& imp = j["impostors"][0];
  // Every far-field triangle of the PVS is in it: at most each box's walls
  // and roof, fewer by the walls facing away from the cell.
  EXPECT_EQ(imp["triangles"], j["stats"]["far_triangles"]);
  EXPECT_LE(imp["triangles"].get<size_t>(), 8u * 10u);
  EXPECT_GT(imp["points"].get<uint64_t>(), 1000u);
  EXPECT_GT(imp["screen_pixels"].get<uint64_t>(), 100u);
  EXPECT_NEAR(imp["points_per_pixel"].get<double>(),
              imp["points"].get<double>() / imp["screen_pixels"].get<double>(), 1e-9);
  // The encoded impostor (what the wire carries) is smaller than in memory.
  EXPECT_GT(imp["bytes"].get<uint64_t>(), 0u);
  EXPECT_LT(imp["bytes"].get<uint64_t>(), imp["stats"]["memory_bytes"].get<uint64_t>());
  EXPECT_GT(imp["bake_s"].get<double>(), 0.0);
  EXPECT_EQ(imp["stats"]["points"], imp["points"]);
  const auto& stats = j["stats"];
  EXPECT_EQ(stats["impostors"], 1);
  EXPECT_EQ(stats["far_triangles"].get<size_t>() + stats["near_triangles"].get<size_t>(),
            stats["pvs_triangles"].get<size_t>());
  EXPECT_EQ(stats["points"], imp["points"]);
  // Kept more precisely, the same points cost more bytes; a colour step the
  // encoding has no code for is refused by name.
  const ToolRun fine = runPvs(common +
                              "--json --min-triangles 20 --max-bytes-ratio 0 "
                              "--position-error 0.0001 --colour-step 1");
  ASSERT_EQ(fine.status, 0) << fine.err;
  const auto fj = nlohmann::json::parse(fine.out);
  ASSERT_EQ(fj["impostors"].size(), 1u);
  EXPECT_EQ(fj["impostors"][0]["points"], imp["points"]);
  EXPECT_GT(fj["impostors"][0]["bytes"].get<uint64_t>(), imp["bytes"].get<uint64_t>());
  // Without thinning nothing is thinned, and the points thinned come back.
  const ToolRun unthinned =
      runPvs(common + "--json --min-triangles 20 --max-bytes-ratio 0 --no-thinning");
  ASSERT_EQ(unthinned.status, 0) << unthinned.err;
  const auto uj = nlohmann::json::parse(unthinned.out);
  ASSERT_EQ(uj["impostors"].size(), 1u);
  EXPECT_EQ(uj["impostors"][0]["stats"]["thinned"], 0);
  EXPECT_EQ(uj["impostors"][0]["points"].get<uint64_t>(),
            imp["points"].get<uint64_t>() + imp["stats"]["thinned"].get<uint64_t>());
  const ToolRun badStep = runPvs(common + "--colour-step 3");
  EXPECT_NE(badStep.status, 0);
  EXPECT_NE(badStep.err.find("--colour-step"), std::string::npos) << badStep.err;
  // The same cell with a heavier threshold keeps its far field as geometry
  // and says so.
  const ToolRun light = runPvs(common + "--json --min-triangles 500");
  ASSERT_EQ(light.status, 0) << light.err;
  const auto lj = nlohmann::json::parse(light.out);
  EXPECT_TRUE(lj["impostors"].empty());
  EXPECT_NE(lj["stats"]["why"].get<std::string>().find("500"), std::string::npos)
      << lj["stats"]["why"];
  // By default an impostor costing more bytes than the faces it replaces is
  // not made: the row (at most 80 triangles) is cheaper as geometry, and its
  // faces are recorded to be streamed as such.
  ASSERT_GT(imp["bytes"].get<uint64_t>(), imp["geometry_bytes"].get<uint64_t>());
  const ToolRun cheaper = runPvs(common + "--json --min-triangles 20");
  ASSERT_EQ(cheaper.status, 0) << cheaper.err;
  const auto cj = nlohmann::json::parse(cheaper.out);
  EXPECT_TRUE(cj["impostors"].empty());
  EXPECT_GE(cj["stats"]["geometry_faces"].get<size_t>(), imp["faces_replaced"].get<size_t>());
  EXPECT_EQ(cj["stats"]["geometry_faces_bytes"], imp["geometry_bytes"]);
  EXPECT_NE(cj["stats"]["why"].get<std::string>().find("left as geometry"), std::string::npos)
      << cj["stats"]["why"];
  // People get a table with one row per impostor and a total.
  const ToolRun table = runPvs(common + "--min-triangles 20 --max-bytes-ratio 0");
  ASSERT_EQ(table.status, 0) << table.err;
  EXPECT_NE(table.out.find("pts/px"), std::string::npos) << table.out;
  EXPECT_NE(table.out.find("total"), std::string::npos) << table.out;
}

TEST(PvsTool, ImpostorsBakeAPvsDatabasesCellsIntoAnImpostorDatabase) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("row.obj", farRowScene());
  const fs::path pvsDb = dir / "row.pvsdb", impDb = dir / "row.impdb";
  const ToolRun bake = runPvs("bake --scene " + scene.string() +
                              " --cell-size 4 --region -4,0,-4,4,4,4 --out " + pvsDb.string());
  ASSERT_EQ(bake.status, 0) << bake.err;
  const std::string common = "impostors --scene " + scene.string() + " --db " + pvsDb.string() +
                             " --out " + impDb.string() +
                             " --near-distance 100 --min-triangles 20 --lighting-cache none "
                             "--max-rays 8 --screen 320x240 --max-bytes-ratio 0";
  const ToolRun r = runPvs(common + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_GT(j["cells"].get<size_t>(), 0u);
  EXPECT_EQ(j["computed_cells"], j["cells"]);
  EXPECT_EQ(j["cells_with_impostors"], j["cells"]);  // every cell sees the row beyond d
  // Cells merged into view cells by default: fewer view cells, each with impostors.
  EXPECT_GT(j["view_cells"].get<size_t>(), 0u);
  EXPECT_LT(j["view_cells"].get<size_t>(), j["cells"].get<size_t>());
  EXPECT_EQ(j["view_cells_with_impostors"], j["view_cells"]);
  EXPECT_GT(j["bytes"].get<uint64_t>(), 0u);
  EXPECT_TRUE(fs::exists(impDb));
  // Neither --cell nor --db, and --db without --out, are refused.
  const ToolRun neither = runPvs("impostors --scene " + scene.string());
  vistream::testing::expectFailedSaying(neither, 1, "--cell or --db");
  const ToolRun noOut = runPvs("impostors --scene " + scene.string() + " --db " + pvsDb.string());
  vistream::testing::expectFailedSaying(noOut, 1, "--out: required with --db");
}

TEST(PvsTool, ImpostorBenchPrintsTable51AndEveryKnobOfTheSweep) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("row.obj", farRowScene());
  const ToolRun r = runPvs("impostor-bench --scenes " + scene.string() +
                           " --cell -2,1,-2,2,3,2 --near-distance 100 --min-triangles 20 "
                           "--repeats 1 --screen 240x180 --lighting-cache none --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j.size(), 1u);
  const auto& table = j[0]["table_5_1"];
  ASSERT_EQ(table.size(), 1u);  // the row is one sector and band
  EXPECT_NEAR(table[0]["points_per_pixel"].get<double>(),
              table[0]["points"].get<double>() / table[0]["screen_pixels"].get<double>(), 1e-9);
  const auto& sweep = j[0]["sweep"];
  std::map<std::string, nlohmann::json> rows;
  for (const auto& row : sweep) rows[row["setting"].get<std::string>()] = row;
  ASSERT_EQ(rows.size(), 15u);
  EXPECT_EQ(j[0]["fov_deg"].get<double>(), 60.0);  // the client's camera
  auto points = [&](const char* s) { return rows.at(s)["points"].get<uint64_t>(); };
  // The defaults are resolution 1, 8x2 texels and variance 4: those rows are
  // the table's impostor again.
  EXPECT_EQ(points("resolution 1.0"), table[0]["points"].get<uint64_t>());
  EXPECT_EQ(points("texture 8x2"), table[0]["points"].get<uint64_t>());
  // Coarser LDIs sample fewer points, at every step of the resolution (removal
  // judges against the spacing they were sized for); removal and hidden
  // culling drop points.
  EXPECT_LT(points("resolution 0.5"), points("resolution 0.7"));
  EXPECT_LT(points("resolution 0.7"), points("resolution 0.8"));
  EXPECT_LT(points("resolution 0.8"), points("resolution 1.0"));
  EXPECT_LT(points("resolution 1.0"), points("resolution 1.4"));
  EXPECT_GT(points("no point removal"), points("resolution 1.0"));
  EXPECT_GT(points("hidden points kept"), points("resolution 1.0"));
  // The pixel filter changes colours, not points.
  EXPECT_EQ(points("pixel filter 0.5"), points("resolution 1.0"));
  // One texel a point is one colour a point, and the smallest.
  EXPECT_DOUBLE_EQ(rows.at("texture 1x1")["single_colour_share"].get<double>(), 1.0);
  EXPECT_LT(rows.at("texture 1x1")["bytes"].get<uint64_t>(),
            rows.at("texture 16x4")["bytes"].get<uint64_t>());
}

TEST(PvsTool, ImpostorArgumentsFailBeforeTheSceneLoadsNamingTheOption) {
  using vistream::testing::expectEachOptionNamed;
  const std::string missing = "/nonexistent/scene.obj";
  vistream::testing::RefusedCommand pvs{
      .tool = "vistream-pvs", .common = "impostors --scene " + missing, .unopened = missing};
  expectEachOptionNamed(pvs, {"--cell 1,2,3"});
  pvs.common = "impostors --scene " + missing + " --cell 0,0,0,1,1,1";
  expectEachOptionNamed(
      pvs, {"--texture 0x2", "--texture eight", "--screen 8x8", "--resolution 0", "--sectors 0",
            "--near-distance -5", "--min-rays 10 --max-rays 5", "--visibility-views 0",
            "--pixel-filter -0.5", "--pixel-filter 5", "--merge-cells 0", "--merge-cells 65"});
}

TEST(PvsTool, BenchPrintsOneRowPerSceneSizeAndMethodWithNoMissingFacesAndTheDistrictBakes) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const ToolRun r = runPvs("bench --scenes " + scene.string() +
                           " --cells 1 --accuracy-cells 2 --gt-res 16 --gt-points 6 --gt-probes 2 "
                           "--district 24 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  // Not indoors: paper, + back faces, + planar fusion and + horizons, at 2,
  // 4, 8 and 16 m.
  const std::vector<std::string> methods{"paper", "+back faces", "+planar fusion", "+horizons"};
  ASSERT_EQ(j["accuracy"].size(), 4 * methods.size());
  std::set<std::pair<double, std::string>> rows;
  for (const auto& row : j["accuracy"]) {
    for (const char* key : {"scene", "method", "cell_size_m", "median_pvs_over_seen",
                            "missing_faces", "ms_per_cell", "seen_by_probes_only"})
      EXPECT_TRUE(row.contains(key)) << key << " in " << row;
    EXPECT_EQ(row["scene"], scene.string());
    EXPECT_EQ(row["missing_faces"].get<size_t>(), 0u) << row;
    EXPECT_GE(row["median_pvs_over_seen"].get<double>(), 1.0) << row;
    rows.emplace(row["cell_size_m"].get<double>(), row["method"].get<std::string>());
  }
  EXPECT_EQ(rows.size(), j["accuracy"].size()) << "one row per cell size and method";
  // The bake: a 24 m square around the scene's centre (the scene is 100 m
  // wide), the same cells for every method, in the order of the table.
  ASSERT_EQ(j["bake"].size(), methods.size());
  for (size_t m = 0; m < methods.size(); ++m) {
    const auto& row = j["bake"][m];
    for (const char* key : {"scene", "method", "cell_size_m", "district_m", "cells", "bake_s"})
      EXPECT_TRUE(row.contains(key)) << key << " in " << row;
    EXPECT_EQ(row["method"], methods[m]);
    EXPECT_EQ(row["district_m"].get<std::vector<double>>(), (std::vector<double>{24, 24}));
    EXPECT_EQ(row["cell_size_m"].get<double>(), 4.0) << "the server's default cell";
    EXPECT_GT(row["cells"].get<size_t>(), 0u);
    EXPECT_EQ(row["cells"], j["bake"][0]["cells"]);
    EXPECT_GE(row["bake_s"].get<double>(), 0.0);
  }
  EXPECT_TRUE(j.contains("total_s"));
}

TEST(PvsTool, ACellFarOutsideTheSceneGetsAWarningAndStillItsPvs) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());  // within x, z in [-50, 50]
  ToolRun r = runPvs("cell --scene " + scene.string() + " --cell 5000,1,5000,5004,2,5004 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("--cell 5000,1,5000,5004,2,5004 lies outside the scene's bounds"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(nlohmann::json::parse(r.out)["faces"].empty());
  r = runPvs("cell --scene " + scene.string() + " --cell -1,1,1,1,2,3 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.err.find("outside the scene's bounds"), std::string::npos) << r.err;
}

TEST(PvsTool, QueryPrintsASummaryAndTheFaceIdsOnlyWhenAsked) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("wall.obj", wallScene());
  const std::string db = (dir / "w.db").string();
  ASSERT_EQ(runPvs("bake --scene " + scene.string() + " --cell-size 4,2,4 --out " + db).status, 0);
  ToolRun r = runPvs("query --db " + db + " --point 0,1.5,1 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto faces = nlohmann::json::parse(r.out)["faces"].get<std::vector<uint32_t>>();
  ASSERT_FALSE(faces.empty());
  std::string ids;
  for (uint32_t f : faces) ids += (ids.empty() ? "" : " ") + std::to_string(f);

  r = runPvs("query --db " + db + " --point 0,1.5,1");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find(std::to_string(faces.size()) + " faces"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(ids + "\n"), std::string::npos) << "IDs without --faces: " << r.out;
  EXPECT_NE(r.out.find("--faces"), std::string::npos) << r.out;
  r = runPvs("query --db " + db + " --point 0,1.5,1 --faces");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("\n" + ids + "\n"), std::string::npos) << r.out;
}

}  // namespace
