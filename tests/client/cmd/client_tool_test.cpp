// vistream-client as a user runs it: headless walks over a local scene and
// over a server, the JSON contract, the three modes side by side, PNG frames,
// and clear errors for bad arguments.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "client/app/walkthrough.h"
#include "client/render/image.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/run_tool.h"
#include "tests/common/support/temp_dir.h"
#include "tests/common/support/tool_checks.h"

namespace {

namespace fs = std::filesystem;
using vistream::testing::runTool;

// A street 300 m long between boxes, open to the sky.
std::string streetObj() {
  vistream::testing::GroundAndBoxesObj o(-60, -320, 60, 20);
  for (int i = 0; i < 30; ++i) {
    o.box("west_" + std::to_string(i), -20, -10.0 * i - 8, -6, -10.0 * i, 6 + (i * 7) % 13);
    o.box("east_" + std::to_string(i), 6, -10.0 * i - 8, 20, -10.0 * i, 5 + (i * 5) % 11);
  }
  return o.obj;
}

const char* kWalk =
    "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,10,0,0\n0.1,0,1.7,9.9,2,0\n0.2,0,1.7,9.8,4,1\n";

nlohmann::json parseJson(const std::string& text) {
  return nlohmann::json::parse(text);
}

// Starts vistream-server on `scene` in `dir` (any free port, streaming within
// 400 m, its log in server.log), runs the shell commands `clients` once the
// port is known ($port in them), then stops the server with SIGTERM and
// waits for it. Returns the shell's status.
int withServer(const vistream::testing::TempDir& dir, const fs::path& scene,
               const std::string& clients) {
  const std::string bin = VISTREAM_BIN_DIR, d = dir.path().string();
  const std::string script =
      bin + "/vistream-server --scene " + scene.string() + " --port 0 --port-file " + d +
      "/port --radius 400 --log-level warn > " + d + "/server.log 2>&1 & echo $! > " + d +
      "/pid; for i in $(seq 1 300); do [ -s " + d + "/port ] && break; sleep 0.1; done; " +
      "port=$(cat " + d + "/port); " + clients + "; kill -TERM $(cat " + d + "/pid); wait $(cat " +
      d + "/pid) 2>/dev/null";
  return std::system(("bash -c '" + script + "'").c_str());
}

// The JSON a connected client run under withServer printed to DIR/net.json,
// once the exit status it left in DIR/status is 0 (null otherwise, with a
// failure showing its stderr from DIR/client.err).
nlohmann::json connectedResult(const vistream::testing::TempDir& dir) {
  std::ifstream st(dir.path() / "status");
  int status = -1;
  st >> status;
  std::ifstream err(dir.path() / "client.err");
  EXPECT_EQ(status, 0) << std::string((std::istreambuf_iterator<char>(err)), {});
  if (status != 0) return nullptr;
  std::ifstream netJson(dir.path() / "net.json");
  return nlohmann::json::parse(std::string((std::istreambuf_iterator<char>(netJson)), {}));
}

// A vistream-client command line connected to withServer's server.
std::string connectedClient(const std::string& args) {
  return std::string(VISTREAM_BIN_DIR) + "/vistream-client --host 127.0.0.1 --port $port " + args;
}

TEST(ClientTool, AHeadlessWalkWritesFramesAndTheJsonContract) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv", kWalk);
  const fs::path out = dir.path() / "frames";
  const auto r =
      runTool("vistream-client",
              "--scene " + scene.string() + " --headless --path " + path.string() +
                  " --frames 3 --size 160x120 --near-distance 40 --polygon-budget 0 --out " +
                  out.string() + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = parseJson(r.out);
  EXPECT_EQ(j["frames"], 3);
  EXPECT_GT(j["mean_frame_ms"].get<double>(), 0.0);
  for (const char* k : {"polygon", "horizon", "cache", "ray_hit", "ray_miss"})
    EXPECT_TRUE(j["pixels"].contains(k)) << k;
  ASSERT_EQ(j["per_frame"].size(), 3u);
  for (const auto& f : j["per_frame"]) {
    const auto& p = f["pixels"];
    const size_t total = p["polygon"].get<size_t>() + p["horizon"].get<size_t>() +
                         p["cache"].get<size_t>() + p["ray_hit"].get<size_t>() +
                         p["ray_miss"].get<size_t>() + p["background"].get<size_t>();
    EXPECT_EQ(total, 160u * 120u) << "every pixel has exactly one class";
    EXPECT_TRUE(f["stages"]["far_field"]["ran"].get<bool>())
        << "the street reaches beyond d = 40 m";
  }
  for (int i = 0; i < 3; ++i) {
    const auto img = vistream::readPng(out / ("frame_0000" + std::to_string(i) + ".png"));
    EXPECT_EQ(img.width, 160);
    EXPECT_EQ(img.height, 120);
  }
}

TEST(ClientTool, TheThreeModesRenderTheSameImagesSideBySide) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv", kWalk);
  std::map<std::string, nlohmann::json> runs;
  for (const std::string mode : {"pipeline", "raycast-all", "geometry-all"}) {
    const auto r = runTool("vistream-client",
                           "--scene " + scene.string() + " --headless --path " + path.string() +
                               " --size 200x150 --near-distance 40 --polygon-budget 0 --mode " +
                               mode + " --out " + (dir.path() / mode).string() + " --json");
    ASSERT_EQ(r.status, 0) << mode << ": " << r.err;
    runs[mode] = parseJson(r.out);
  }
  for (const auto& f : runs["raycast-all"]["per_frame"])
    EXPECT_EQ(f["pixels"]["ray_hit"].get<size_t>() + f["pixels"]["ray_miss"].get<size_t>(),
              200u * 150u);
  for (const auto& f : runs["geometry-all"]["per_frame"]) {
    EXPECT_EQ(f["pixels"]["ray_hit"].get<size_t>() + f["pixels"]["ray_miss"].get<size_t>(), 0u);
    EXPECT_EQ(f["pixels"]["polygon"].get<size_t>() + f["pixels"]["background"].get<size_t>(),
              200u * 150u);
  }
  for (int i = 0; i < 3; ++i) {
    const std::string name = "frame_0000" + std::to_string(i) + ".png";
    const auto ref = vistream::readPng(dir.path() / "raycast-all" / name);
    for (const std::string mode : {"pipeline", "geometry-all"}) {
      const auto d = vistream::compareImages(vistream::readPng(dir.path() / mode / name), ref);
      EXPECT_LT(d.differingFraction, 0.01) << mode << " frame " << i;
    }
  }
}

TEST(ClientTool, ConnectedHeadlessRendersWhatTheServerStreams) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv", kWalk);
  const std::string d = dir.path().string();
  // The server streams within 400 m, so it sends the whole street and the
  // connected frames must match the local ones.
  ASSERT_EQ(withServer(dir, scene,
                       connectedClient("--headless --path " + path.string() +
                                       " --size 160x120 --near-distance 40 --out " + d +
                                       "/net --json > " + d + "/net.json 2> " + d +
                                       "/client.err; echo $? > " + d + "/status")),
            0);
  const auto j = connectedResult(dir);
  ASSERT_FALSE(j.is_null());
  // Taking up geometry is part of each frame's wall-clock time.
  EXPECT_GE(j["geometry_intake_ms_total"].get<double>(), 0.0);
  EXPECT_GE(
      j["wall_ms_per_frame"].get<double>(),
      j["mean_frame_ms"].get<double>() + j["geometry_intake_ms_per_frame"].get<double>() - 1e-9);
  const auto local = runTool("vistream-client",
                             "--scene " + scene.string() + " --headless --path " + path.string() +
                                 " --size 160x120 --near-distance 40 --out " + d + "/local --json");
  ASSERT_EQ(local.status, 0) << local.err;
  for (int i = 0; i < 3; ++i) {
    const std::string name = "frame_0000" + std::to_string(i) + ".png";
    const auto diff = vistream::compareImages(vistream::readPng(dir.path() / "net" / name),
                                              vistream::readPng(dir.path() / "local" / name));
    // Streamed corners are quantized to 16 bits, which may move an edge by a pixel.
    EXPECT_LT(diff.differingFraction, 0.02) << "frame " << i;
  }
}

// Two connected clients: one stands 6 m down the street, the other walks
// towards it and draws it: the server reports the user, the client fetches
// the Fox over the connection and shows it, and says so per frame.
TEST(ClientTool, AConnectedClientDrawsAnotherUserAsTheServersAvatarModel) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  std::string stand = "t,x,y,z,yaw_deg,pitch_deg\n", walk = stand;
  // Both render in real time (the server reports users twice a second): the
  // standing one for 4 s, the walker for 3 s from 0.3 s later.
  for (int i = 0; i < 120; ++i) stand += std::to_string(i / 30.0) + ",0,1.7,4,180,0\n";
  for (int i = 0; i < 90; ++i) walk += std::to_string(i / 30.0) + ",0,1.7,10,0,-5\n";
  const fs::path standPath = dir.write("stand.csv", stand), walkPath = dir.write("walk.csv", walk);
  const std::string d = dir.path().string();
  ASSERT_EQ(
      withServer(dir, scene,
                 connectedClient("--headless --path " + standPath.string() +
                                 " --size 64x48 --realtime > /dev/null 2>&1 & standing=$!;") +
                     " sleep 0.3; " +
                     connectedClient("--headless --path " + walkPath.string() +
                                     " --size 160x120 --near-distance 40 --realtime --json > " + d +
                                     "/net.json 2> " + d + "/client.err; echo $? > " + d +
                                     "/status; wait $standing")),
      0);
  const auto j = connectedResult(dir);
  ASSERT_FALSE(j.is_null());
  size_t shown = 0;
  for (const auto& f : j["per_frame"])
    if (f["avatars"]["in_view"].get<size_t>() == 1 && f["avatars"]["pixels"].get<size_t>() > 20)
      ++shown;
  EXPECT_GT(shown, 30u) << j["stages"].dump();  // of 90 frames, after the first second
}

TEST(ClientTool, BadArgumentsGetAClearErrorAndANonZeroExit) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv", kWalk);
  const std::string common = "--scene " + scene.string() + " --headless --path " + path.string();
  const std::pair<std::string, std::string> cases[] = {
      {common + " --size 640by480", "--size"},
      {common + " --size 8x8", "--size"},
      {common + " --mode fancy", "--mode"},
      {common + " --frames 99", "--frames"},
      {common + " --horizon-subsample 0", "--horizon-subsample"},
      {"--headless --path " + path.string(), "--scene"},
      {"--scene " + scene.string() + " --headless", "--path"},
      {"--scene " + scene.string() + " --headless --path " + (dir.path() / "missing.csv").string(),
       "missing.csv"},
      {"--host 127.0.0.1 --port 1 --headless --path " + path.string(), "127.0.0.1:1"},
      {common + " --avatars 2 --avatar-model " + (dir.path() / "nofox.glb").string(), "nofox.glb"},
      {common + " --avatars 2 --avatar-model " + scene.string(), "street.obj"},  // no skin
      {"--host 127.0.0.1 --port 1 --headless --avatars 2 --path " + path.string(), "--avatars"},
  };
  for (const auto& [args, mention] : cases) {
    const auto r = runTool("vistream-client", args);
    EXPECT_NE(r.status, 0) << args;
    EXPECT_NE(r.err.find(mention), std::string::npos) << args << "\n" << r.err;
  }
  const auto help = runTool("vistream-client", "--help");
  EXPECT_EQ(help.status, 0);
  EXPECT_NE(help.out.find("--headless"), std::string::npos);
  EXPECT_EQ(runTool("vistream-client-bench", "--help").status, 0);
}

// The impostor image benchmark on a small street cell of city1: every far
// field it compares is measured against the same supersampled reference,
// and the impostors must fill in most of what the client without them lacks.
TEST(ClientTool, TheImpostorImageBenchComparesEveryFarFieldWithTheReference) {
  vistream::testing::TempDir dir;
  const fs::path png = dir.path() / "crops.png";
  const auto r = runTool("bench_impostor_image",
                         "--scene city1 --cell 0,1,0,4,3,4 --near-distance 40 --min-triangles 30 "
                         "--frames 3 --size 120x90 --supersample 2 --json --png " +
                             png.string());
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json j = parseJson(r.out);
  ASSERT_GT(j["impostors"].size(), 0u);
  EXPECT_GT(j["footprint_pixels"].get<size_t>(), 0u);
  std::map<std::string, double> mae;
  for (const auto& m : j["modes"]) mae[m["mode"].get<std::string>()] = m["footprint_mae"];
  ASSERT_EQ(mae.size(), 4u) << j["modes"].dump();
  EXPECT_LT(2.0 * mae["impostors"], mae["held-only"]) << j["modes"].dump();
  EXPECT_GT(mae["held-only"], 0.0);
  const vistream::ImageRgb8 crops = vistream::readPng(png);
  EXPECT_GT(crops.width, 4 * crops.height / 2);  // five crops side by side
  const auto bad = runTool("bench_impostor_image", "--cell 1,2,3 --frames 2");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.err.find("--cell"), std::string::npos) << bad.err;
  EXPECT_EQ(runTool("bench_impostor_image", "--help").status, 0);
}

// Simulated users walk beside the path as Fox avatars: the JSON says per
// frame how many were in view and why, frames show them (orange pixels the
// walk without them lacks), and the summary counts the frames they ran in.
TEST(ClientTool, AvatarsWalkBesideTheHeadlessPathAndSayWhyTheyRan) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  std::string walk = "t,x,y,z,yaw_deg,pitch_deg\n";  // 30 m at 1.5 m/s
  for (int i = 0; i < 100; ++i)
    walk += std::to_string(i / 5.0) + ",0,1.7," + std::to_string(10.0 - 0.3 * i) + ",0,-5\n";
  const fs::path path = dir.write("walk.csv", walk);
  const std::string common = "--scene " + scene.string() + " --headless --json --size 160x120 " +
                             "--path " + path.string();
  const auto with =
      runTool("vistream-client", common + " --avatars 4 --out " + (dir.path() / "with").string());
  ASSERT_EQ(with.status, 0) << with.err;
  const auto without =
      runTool("vistream-client", common + " --out " + (dir.path() / "without").string());
  ASSERT_EQ(without.status, 0) << without.err;
  const nlohmann::json j = parseJson(with.out);
  ASSERT_TRUE(j["stages"].contains("avatars"));
  EXPECT_GE(j["stages"]["avatars"]["frames_ran"].get<size_t>(), 60u);
  for (const auto& f : j["per_frame"]) {
    const auto& a = f["avatars"];
    // The walker 6 m ahead is in view until the path's end turns it back
    // (from 24 m, frame 80).
    if (f["frame"].get<size_t>() < 60) {
      EXPECT_GE(a["in_view"].get<size_t>(), 1u);
    }
    EXPECT_EQ(
        a["in_view"].get<size_t>() + a["beyond_d"].get<size_t>() + a["outside_view"].get<size_t>(),
        4u);
    EXPECT_NE(a["why"].get<std::string>().find("in view"), std::string::npos);
  }
  EXPECT_FALSE(parseJson(without.out)["per_frame"][0].contains("avatars"));
  // Where the frames differ, the one with avatars shows the Fox's orange.
  const auto a = vistream::readPng(dir.path() / "with" / "frame_00010.png");
  const auto b = vistream::readPng(dir.path() / "without" / "frame_00010.png");
  size_t differ = 0, orange = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const glm::u8vec3 c = a.at(x, y);
      if (c == b.at(x, y)) continue;
      ++differ;
      orange += c.r > c.b + 40;
    }
  EXPECT_GT(differ, 100u);
  EXPECT_GT(orange, differ / 2);
}

TEST(ClientTool, AServerThatSendsGarbageEndsTheClientWithAClearError) {
  vistream::testing::TempDir dir;
  const fs::path path = dir.write("walk.csv", kWalk);
  const std::string d = dir.path().string();
  // A "server" that answers every connection with an HTTP error page.
  const fs::path fake = dir.write("fake.py",
                                  "import socket\n"
                                  "s = socket.socket(); s.bind(('127.0.0.1', 0)); s.listen(1)\n"
                                  "open('" +
                                      d +
                                      "/port', 'w').write(str(s.getsockname()[1]))\n"
                                      "c, _ = s.accept(); c.sendall(b'HTTP/1.1 400 Bad "
                                      "Request\\r\\n\\r\\n'); c.recv(1024); c.close()\n");
  const std::string script = "python3 " + fake.string() + " & for i in $(seq 1 100); do [ -s " + d +
                             "/port ] && break; sleep 0.1; done; " + VISTREAM_BIN_DIR +
                             "/vistream-client --host 127.0.0.1 --port $(cat " + d +
                             "/port) --headless --path " + path.string() + " > " + d + "/out 2> " +
                             d + "/err; echo $? > " + d + "/status; wait";
  ASSERT_EQ(std::system(("bash -c '" + script + "'").c_str()), 0);
  std::ifstream st(dir.path() / "status");
  int status = 0;
  st >> status;
  std::ifstream err(dir.path() / "err");
  const std::string text((std::istreambuf_iterator<char>(err)), {});
  EXPECT_EQ(status, 1);
  EXPECT_NE(text.find("bad frame from the server"), std::string::npos) << text;
}

// Bad input and first use (issue 12).
TEST(ClientTool, OutOfRangeNumbersFailAtParseTimeNamingTheOption) {
  using vistream::testing::expectEachOptionNamed;
  // Each error must begin with the option's name (and, for the client, a colon).
  vistream::testing::RefusedCommand client{
      .tool = "vistream-client",
      .common = "--scene /nonexistent/scene.obj --headless --path auto",
      .afterName = ":"};
  expectEachOptionNamed(
      client, {"--frames -5", "--frames 0", "--near-distance -5", "--stream-radius 0", "--fov 0",
               "--horizon-cell -1", "--pixel-budget -1"});
  client.common = "--host 127.0.0.1 --headless --path auto";
  expectEachOptionNamed(client, {"--port 99999"});
  const vistream::testing::RefusedCommand bench{.tool = "vistream-client-bench"};
  expectEachOptionNamed(bench, {"--frames -5", "--frames 1", "--repeats 0", "--speed -1"});
}

TEST(ClientTool, HelpShowsDefaultsCapturedFromTheCode) {
  for (const char* tool : {"vistream-client", "vistream-client-bench"})
    vistream::testing::expectHelpShowsCapturedDefaults(tool, "=640x480");
}

// Connected with --scene: the local copy only generates --path auto, the
// geometry still streams, and --json says what arrived and how long the walk
// waited for it.
TEST(ClientTool, ConnectedHeadlessWalksPathAutoThroughALocalCopyAndReportsWhatItReceived) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv", kWalk);
  const std::string d = dir.path().string();
  ASSERT_EQ(withServer(
                dir, scene,
                connectedClient("--scene " + scene.string() +
                                " --headless --path auto --frames 4 --size 160x120 --json > " + d +
                                "/net.json 2> " + d + "/client.err; echo $? > " + d + "/status; ") +
                    connectedClient("--scene " + scene.string() + " --headless --path " +
                                    path.string() + " > /dev/null 2> " + d +
                                    "/both.err; echo $? > " + d + "/both.status")),
            0);
  auto read = [&](const char* name) {
    std::ifstream f(dir.path() / name);
    return std::string((std::istreambuf_iterator<char>(f)), {});
  };
  ASSERT_EQ(std::stoi(read("status")), 0) << read("client.err");
  const auto j = parseJson(read("net.json"));
  EXPECT_EQ(j["frames"].get<int>(), 4);
  ASSERT_TRUE(j.contains("connection")) << j.dump();
  EXPECT_GT(j["connection"]["bytes_received"].get<uint64_t>(), 0u);
  EXPECT_GE(j["connection"]["wait_for_geometry_ms"].get<double>(), 0.0);
  EXPECT_EQ(j["connection"]["waits"].get<int>(), 5) << "the first view cell and one per frame";
  // A path file with --host and --scene: the scene would be loaded for nothing.
  EXPECT_EQ(std::stoi(read("both.status")), 1);
  EXPECT_NE(read("both.err").find("--scene with --host"), std::string::npos) << read("both.err");
}

// The lit frames of the real city model and of city1 along generated walks
// (the measure): hundreds of colours, none nearly uniform; and
// --sheet adds one row of 4 frames a run to the same PNG.
TEST(ClientTool, LitFramesOfRealAndGeneratedCitiesAreNeverNearlyUniform) {
  vistream::testing::TempDir dir;
  const std::string delfshaven = std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj";
  const std::string sheet = (dir.path() / "sheet.png").string();
  const auto walk =
      runTool("vistream-scene", "path --scene " + delfshaven + " --frames 300 --seed 3 --out " +
                                    (dir.path() / "walk.csv").string());
  ASSERT_EQ(walk.status, 0) << walk.err;
  int rows = 0;
  for (const std::string& args : {std::string("--scene city1 --path auto --frames 24"),
                                  "--scene " + delfshaven + " --path " +
                                      (dir.path() / "walk.csv").string() + " --frames 24"}) {
    const auto r =
        runTool("vistream-client", args + " --headless --size 320x240 --json --sheet " + sheet);
    ASSERT_EQ(r.status, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_GE(j["contrast"]["min_distinct_colours"].get<double>(), 100.0) << args;
    EXPECT_GE(j["contrast"]["min_luminance_std"].get<double>(), 10.0) << args;
    ++rows;
    const vistream::ImageRgb8 png = vistream::readPng(sheet);
    EXPECT_EQ(png.width, 4 + 4 * (320 + 4));
    EXPECT_EQ(png.height, rows * (4 + 240 + 4));
  }
}

}  // namespace

// Avatar self-shadowing (issue 15): the benchmark's machine contract on the
// Fox, and its errors for bad models.
TEST(ClientTool, TheShadowBenchmarkPrintsItsContractKeysForTheFox) {
  const std::string fox = std::string(VISTREAM_SHARED_DIR) + "/data/Fox.glb";
  const auto r = runTool("vistream-client-bench",
                         "--shadows --model " + fox + " --quick --shadow-frames 2 --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"vertices", "triangles", "fps", "ms_per_frame", "l2_error",
                          "mc_ms_equal_error", "breakdown"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["triangles"].get<int>(), 576);  // the Fox's, from its README
  EXPECT_GT(j["vertices"].get<int>(), 0);
  EXPECT_NEAR(j["fps"].get<double>() * j["ms_per_frame"].get<double>(), 1000.0, 1e-6);
  // Within the paper's 2.5-8% of the converged reference.
  EXPECT_GT(j["l2_error"].get<double>(), 0.0);
  EXPECT_LT(j["l2_error"].get<double>(), 0.08);
  double shares = 0.0;
  for (const char* part : {"rasterization", "integration", "transform", "other"})
    shares += j["breakdown"][part].get<double>();
  EXPECT_NEAR(shares, 1.0, 0.02);
  EXPECT_GE(j["knobs"].size(), 4u);
}

// The figure: the Fox unshadowed, by this method and by Monte Carlo. The
// shadows change the picture, and ours is closer to Monte Carlo's than the
// unshadowed one is.
TEST(ClientTool, TheShadowFigureShowsOursCloserToMonteCarloThanNoShadows) {
  vistream::testing::TempDir dir;
  const std::string fox = std::string(VISTREAM_SHARED_DIR) + "/data/Fox.glb";
  const fs::path png = dir.path() / "fox.png";
  const auto r = runTool("vistream-client-bench", "--shadows --model " + fox +
                                                      " --quick --shadow-frames 2 --shadow-png " +
                                                      png.string() + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const vistream::ImageRgb8 sheet = vistream::readPng(png);
  // Three 320 x 320 tiles with 4-pixel gaps around them.
  ASSERT_EQ(sheet.width, 3 * 320 + 4 * 4);
  ASSERT_EQ(sheet.height, 320 + 2 * 4);
  auto tile = [&](int k) {
    vistream::ImageRgb8 t(320, 320);
    for (int y = 0; y < 320; ++y)
      for (int x = 0; x < 320; ++x) t.set(x, y, sheet.at(4 + k * (320 + 4) + x, 4 + y));
    return t;
  };
  const auto open = tile(0), ours = tile(1), reference = tile(2);
  // Over the fox's pixels: those not of the background (the corner's colour).
  const glm::u8vec3 background = reference.at(0, 0);
  size_t foxPixels = 0;
  auto meanDifference = [&](const vistream::ImageRgb8& a, const vistream::ImageRgb8& b) {
    double sum = 0.0;
    foxPixels = 0;
    for (int y = 0; y < 320; ++y)
      for (int x = 0; x < 320; ++x) {
        if (reference.at(x, y) == background) continue;
        ++foxPixels;
        for (int c = 0; c < 3; ++c) sum += std::abs(int(a.at(x, y)[c]) - int(b.at(x, y)[c]));
      }
    return sum / double(3 * std::max<size_t>(1, foxPixels));
  };
  EXPECT_GT(meanDifference(open, reference), 2.0);  // the shadows show
  EXPECT_GT(foxPixels, 5000u);                      // and so does the fox
  EXPECT_LT(meanDifference(ours, reference), 0.5 * meanDifference(open, reference));
}

TEST(ClientTool, TheShadowBenchmarkRefusesAModelItCannotAnimate) {
  vistream::testing::TempDir dir;
  const fs::path obj = dir.write("box.obj", streetObj());
  const vistream::testing::RefusedCommand bench{.tool = "vistream-client-bench",
                                                .common = "--shadows --quick",
                                                .at = vistream::testing::MentionAt::Anywhere};
  const vistream::testing::BadArguments cases[] = {
      {"", "--shadows needs --model"},
      {"--model " + obj.string(), obj.string() + ": has no animation"},
      {"--model " + (dir.path() / "missing.glb").string(),
       (dir.path() / "missing.glb").string() + ": no such file"},
      {"--model " + obj.string() + " --subdivide 9", "--subdivide"},
  };
  vistream::testing::expectEachRefused(bench, cases);
}
