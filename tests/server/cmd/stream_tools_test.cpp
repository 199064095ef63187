// End-to-end tests of vistream-server and vistream-loadtest as a user runs
// them: a server configured from a file, clients walking a path over TCP,
// the load tester's JSON contract, and SIGTERM stopping the server cleanly.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/common/support/box_scenes.h"
#include "tests/common/support/run_tool.h"
#include "tests/common/support/temp_dir.h"

namespace {

namespace fs = std::filesystem;
using vistream::testing::runTool;
using vistream::testing::ToolRun;

// A street: ground, two rows of boxes, a wall at the end.
std::string streetObj() {
  std::string o = "o ground\nv -40 0 -40\nv -40 0 40\nv 40 0 40\nv 40 0 -40\nf 1 2 3 4\n";
  int base = 5;
  auto box = [&](const std::string& name, double x0, double z0, double x1, double z1, double h) {
    vistream::testing::appendBoxObj(o, base, name, x0, z0, x1, z1, h);
  };
  for (int i = 0; i < 6; ++i) {
    box("west_" + std::to_string(i), -12, -30 + 10 * i, -6, -24 + 10 * i, 8);
    box("east_" + std::to_string(i), 6, -30 + 10 * i, 12, -24 + 10 * i, 8);
  }
  box("end_wall", -20, -36, 20, -35, 12);
  return o;
}

std::string sh(const std::string& script) {
  FILE* p = ::popen(("bash -c '" + script + "' 2>&1").c_str(), "r");
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  ::pclose(p);
  return out;
}

TEST(StreamTools, AServerFromAConfigFileServesWalkingClientsAndStopsOnSigterm) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path = dir.write("walk.csv",
                                  "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,20,0,0\n4,0,1.7,14.4,0,0\n8,0,1.7,8.8,0,0\n");
  const fs::path config = dir.write("server.ini", "scene=" + scene.string() + "\nport=0\nport-file=" +
                                                      (dir.path() / "port").string() + "\nradius=60\nlog-level=warn\n");
  const std::string bin = VISTREAM_BIN_DIR;
  const std::string d = dir.path().string();
  sh(bin + "/vistream-server --config " + config.string() + " > " + d + "/server.log 2>&1 & echo $! > " + d +
     "/pid; for i in $(seq 1 200); do [ -s " + d + "/port ] && break; sleep 0.1; done; " + bin +
     "/vistream-loadtest --port $(cat " + d + "/port) --clients 3 --path " + path.string() +
     " --duration 2 --speed 1 --scene " + scene.string() + " --check-every 3 --json > " + d + "/out.json; echo $? > " +
     d + "/lt_status; kill -TERM $(cat " + d + "/pid); wait $(cat " + d + "/pid) 2>/dev/null; sleep 0.5");
  std::ifstream ltStatus(dir.path() / "lt_status");
  int status = -1;
  ltStatus >> status;
  std::ifstream log(dir.path() / "server.log");
  const std::string serverLog((std::istreambuf_iterator<char>(log)), {});
  ASSERT_EQ(status, 0) << serverLog;
  std::ifstream out(dir.path() / "out.json");
  const auto j = nlohmann::json::parse(out);
  for (const char* key : {"clients", "duration_s", "bytes_per_client_per_s", "cell_ready_latency_ms", "visibility_misses",
                          "frames_checked", "initial_load_ms", "errors", "server_cpu_ms_per_s_per_client"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"p50", "p95", "p99"}) EXPECT_TRUE(j["cell_ready_latency_ms"].contains(key)) << key;
  EXPECT_EQ(j["clients"], 3);
  EXPECT_EQ(j["errors"], 0);
  EXPECT_EQ(j["clients_loaded"], 3);
  EXPECT_GT(j["frames_checked"].get<int>(), 0);
  EXPECT_EQ(j["visibility_misses"], 0);
  EXPECT_GT(j["bytes_per_client_per_s"].get<double>(), 0.0);
  // SIGTERM: the server said goodbye and exited (no process left).
  EXPECT_EQ(sh("kill -0 $(cat " + d + "/pid) 2>/dev/null && echo alive || echo gone"), "gone\n");
}

TEST(StreamTools, HelpAndBadArgumentsGiveClearExits) {
  for (const char* tool : {"vistream-server", "vistream-loadtest"}) {
    const ToolRun help = runTool(tool, "--help");
    EXPECT_EQ(help.status, 0) << tool;
    EXPECT_NE(help.out.find("--port"), std::string::npos) << tool;
  }
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  ToolRun r = runTool("vistream-server", "--scene " + scene.string() + " --policy nearest");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("--policy"), std::string::npos) << r.err;
  r = runTool("vistream-server", "--scene " + scene.string() + " --token-file " + (dir.path() / "none").string());
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("none"), std::string::npos) << r.err;
  r = runTool("vistream-server", "--no-such-option");
  EXPECT_EQ(r.status, 2);
  r = runTool("vistream-loadtest", "--clients 2 --path a.csv --paths auto");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("--path"), std::string::npos) << r.err;
  r = runTool("vistream-loadtest", "--clients 0 --path " + dir.write("p.csv", "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,0,0,0\n").string());
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("--clients"), std::string::npos) << r.err;
}

}  // namespace
