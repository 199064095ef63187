// End-to-end tests of vistream-server and vistream-loadtest as a user runs
// them: a server configured from a file, clients walking a path over TCP,
// the load tester's JSON contract, SIGTERM stopping the server cleanly, and
// the load tester failing (exit 1, in bounded time) against servers that
// accept connections but serve nothing.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <atomic>
#include <boost/asio.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "protocol/wire/messages.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/run_tool.h"
#include "tests/common/support/temp_dir.h"
#include "tests/common/support/tool_checks.h"

namespace {

namespace fs = std::filesystem;
namespace asio = boost::asio;
using asio::ip::tcp;
using vistream::testing::runTool;
using vistream::testing::ToolRun;

// A TCP server on 127.0.0.1 (an ephemeral port) that accepts every
// connection and then serves nothing: `Silent` never reads or sends a byte;
// `WelcomeThenSilent` reads the client's first bytes (its Hello), answers with
// one valid Welcome, built as vistream-server builds it, and then neither
// reads nor sends again. Connections stay open until the server is destroyed.
class StallingServer {
 public:
  enum class Behaviour { Silent, WelcomeThenSilent };

  explicit StallingServer(Behaviour behaviour)
      : behaviour_(behaviour),
        acceptor_(io_, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0)) {
    port_ = acceptor_.local_endpoint().port();
    accept();
    thread_ = std::thread([this] { io_.run(); });
  }
  ~StallingServer() {
    io_.stop();
    thread_.join();
  }
  StallingServer(const StallingServer&) = delete;
  StallingServer& operator=(const StallingServer&) = delete;

  uint16_t port() const { return port_; }
  size_t welcomesSent() const { return welcomesSent_.load(); }

 private:
  // A grid of 8 x 1 x 8 cells of 10 m around the origin, 100 faces.
  static std::vector<uint8_t> welcomeFrame() {
    namespace wire = vistream::wire;
    wire::WelcomeT w;
    w.protocol_version = wire::kProtocolVersion;
    w.scene_id = "stalling";
    w.session_id = 1;
    w.bounds_min = std::make_unique<wire::Vec3d>(-40.0, 0.0, -40.0);
    w.bounds_max = std::make_unique<wire::Vec3d>(40.0, 10.0, 40.0);
    w.local_origin = std::make_unique<wire::Vec3d>(0.0, 0.0, 0.0);
    w.grid = std::make_unique<wire::CellGridT>();
    w.grid->origin = std::make_unique<wire::Vec3f>(-40.0f, 0.0f, -40.0f);
    w.grid->cell_size = std::make_unique<wire::Vec3f>(10.0f, 10.0f, 10.0f);
    w.grid->dims = std::make_unique<wire::CellIndex>(8, 1, 8);
    w.face_count = 100;
    w.near_field_radius_m = 60.0f;
    w.policy = "visibility";
    w.quant_origin = std::make_unique<wire::Vec3d>(-40.0, 0.0, -40.0);
    w.quant_step = 1e-3;
    return wire::encodeMessage(std::move(w));
  }

  void accept() {
    acceptor_.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
      if (ec) return;
      auto s = std::make_shared<tcp::socket>(std::move(socket));
      sockets_.push_back(s);
      if (behaviour_ == Behaviour::WelcomeThenSilent) {
        auto hello = std::make_shared<std::vector<uint8_t>>(4096);
        s->async_read_some(
            asio::buffer(*hello), [this, s, hello](const boost::system::error_code& rec, size_t) {
              if (rec) return;
              auto frame = std::make_shared<std::vector<uint8_t>>(welcomeFrame());
              asio::async_write(*s, asio::buffer(*frame),
                                [this, s, frame](const boost::system::error_code& wec, size_t) {
                                  if (!wec) ++welcomesSent_;
                                });
            });
      }
      accept();
    });
  }

  Behaviour behaviour_;
  asio::io_context io_;
  tcp::acceptor acceptor_;
  uint16_t port_ = 0;
  std::vector<std::shared_ptr<tcp::socket>> sockets_;  // only touched on io_'s thread
  std::atomic<size_t> welcomesSent_{0};
  std::thread thread_;
};

// Generous slack for the upper bounds on run time below: they catch a load
// tester that hangs, not a slow one (the test machine is noisy).
constexpr double kSlackS = 10.0;

// A 10 m walk inside the stalling server's grid.
constexpr const char* kShortWalk = "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,0,0,0\n4,0,1.7,10,0,0\n";

struct TimedRun {
  ToolRun run;  // status 124 or 137: killed by timeout(1) at the bound
  double seconds = 0.0;
  nlohmann::json json;  // discarded if stdout is not one JSON object
};

// Runs vistream-loadtest with `args` and times it. A run longer than
// `boundS` + 2 s is killed (timeout(1)), so a load tester that hangs fails
// the test instead of hanging it.
TimedRun timedLoadTest(const vistream::testing::TempDir& dir, const std::string& args,
                       double boundS) {
  TimedRun t;
  const fs::path errFile = dir.path() / "loadtest.err";
  const std::string cmd = fmt::format("timeout -k 1 {:.0f} {}/vistream-loadtest {} 2>{}",
                                      boundS + 2.0, VISTREAM_BIN_DIR, args, errFile.string());
  const auto start = std::chrono::steady_clock::now();
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return t;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) t.run.out.append(buf, n);
  const int status = ::pclose(pipe);
  t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  t.run.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream err(errFile);
  t.run.err.assign(std::istreambuf_iterator<char>(err), {});
  t.json = nlohmann::json::parse(t.run.out, nullptr, false);
  return t;
}

// A load test of kShortWalk against a StallingServer, run once at
// construction. The server lives as long as this object, so a test can ask it
// what it sent. The run may take --duration + --grace, plus kSlackS.
struct StalledLoadTest {
  StalledLoadTest(StallingServer::Behaviour behaviour, int clients, double durationS, double graceS,
                  const std::string& options)
      : server(behaviour), boundS(durationS + graceS + kSlackS) {
    const fs::path path = dir.write("walk.csv", kShortWalk);
    t = timedLoadTest(
        dir,
        fmt::format("--port {} --clients {} --path {} --duration {} --grace {} {}", server.port(),
                    clients, path.string(), durationS, graceS, options),
        boundS);
  }

  // Expects the run to have failed (status 1) before the bound, with a JSON
  // summary on stdout in which no client loaded and `failed` clients failed,
  // all for `reason`. Fatal if there is no JSON: call it in
  // ASSERT_NO_FATAL_FAILURE.
  void expectNoClientLoaded(int failed, const std::string& reason) const {
    EXPECT_EQ(t.run.status, 1) << t.run.err;
    EXPECT_LT(t.seconds, boundS);
    ASSERT_FALSE(t.json.is_discarded()) << t.run.out;
    EXPECT_EQ(t.json["clients_loaded"], 0);
    EXPECT_EQ(t.json["errors"], failed);
    EXPECT_EQ(t.json["errors_by_reason"], nlohmann::json({{reason, failed}}));
  }

  StallingServer server;
  vistream::testing::TempDir dir;
  double boundS;
  TimedRun t;
};

// A street: ground, two rows of boxes, a wall at the end.
std::string streetObj() {
  vistream::testing::GroundAndBoxesObj o(-40, -40, 40, 40);
  for (int i = 0; i < 6; ++i) {
    o.box("west_" + std::to_string(i), -12, -30 + 10 * i, -6, -24 + 10 * i, 8);
    o.box("east_" + std::to_string(i), 6, -30 + 10 * i, 12, -24 + 10 * i, 8);
  }
  o.box("end_wall", -20, -36, 20, -35, 12);
  return o.obj;
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
  const fs::path path = dir.write(
      "walk.csv", "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,20,0,0\n4,0,1.7,14.4,0,0\n8,0,1.7,8.8,0,0\n");
  const fs::path config =
      dir.write("server.ini", "scene=" + scene.string() + "\nport=0\nport-file=" +
                                  (dir.path() / "port").string() + "\nradius=60\nlog-level=warn\n");
  const std::string bin = VISTREAM_BIN_DIR;
  const std::string d = dir.path().string();
  sh(bin + "/vistream-server --config " + config.string() + " > " + d +
     "/server.log 2>&1 & echo $! > " + d + "/pid; for i in $(seq 1 200); do [ -s " + d +
     "/port ] && break; sleep 0.1; done; " + bin + "/vistream-loadtest --port $(cat " + d +
     "/port) --clients 3 --path " + path.string() + " --duration 2 --speed 1 --scene " +
     scene.string() + " --check-every 3 --json > " + d + "/out.json; echo $? > " + d +
     "/lt_status; kill -TERM $(cat " + d + "/pid); wait $(cat " + d +
     "/pid) 2>/dev/null; sleep 0.5");
  std::ifstream ltStatus(dir.path() / "lt_status");
  int status = -1;
  ltStatus >> status;
  std::ifstream log(dir.path() / "server.log");
  const std::string serverLog((std::istreambuf_iterator<char>(log)), {});
  ASSERT_EQ(status, 0) << serverLog;
  std::ifstream out(dir.path() / "out.json");
  const auto j = nlohmann::json::parse(out);
  for (const char* key : {"clients", "duration_s", "bytes_per_client_per_s",
                          "cell_ready_latency_ms", "visibility_misses", "frames_checked",
                          "initial_load_ms", "errors", "server_cpu_ms_per_s_per_client"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"p50", "p95", "p99"})
    EXPECT_TRUE(j["cell_ready_latency_ms"].contains(key)) << key;
  EXPECT_EQ(j["clients"], 3);
  EXPECT_EQ(j["errors"], 0) << j.dump();
  EXPECT_EQ(j["clients_loaded"], 3);
  EXPECT_EQ(j["clients_not_loaded"], 0);
  EXPECT_EQ(j["clients_cut_off"], 0);
  EXPECT_EQ(j["cut_off_clients"], nlohmann::json::array());
  EXPECT_EQ(j["errors_by_reason"], nlohmann::json::object());
  EXPECT_EQ(j["failed_clients"], nlohmann::json::array());
  EXPECT_EQ(j["first_error"], "");
  EXPECT_GT(j["frames_checked"].get<int>(), 0);
  EXPECT_EQ(j["visibility_misses"], 0);
  EXPECT_GT(j["bytes_per_client_per_s"].get<double>(), 0.0);
  // The byte breakdown by message type sums to the bytes received (a frame
  // cut off at the end counts as partial_frame), and says what carried them.
  uint64_t byType = 0;
  for (const auto& [type, bytes] : j["bytes_by_type"].items()) byType += bytes.get<uint64_t>();
  EXPECT_EQ(byType, j["bytes_received"].get<uint64_t>()) << j["bytes_by_type"].dump();
  for (const char* type : {"Welcome", "Geometry", "CellReady"}) {
    EXPECT_GT(j["bytes_by_type"].value(type, uint64_t(0)), 0u) << type;
    EXPECT_GT(j["frames_by_type"].value(type, uint64_t(0)), 0u) << type;
  }
  EXPECT_EQ(j["frames_by_type"]["Welcome"], 3) << "one Welcome per client";
  // SIGTERM: the server said goodbye and exited (no process left).
  EXPECT_EQ(sh("kill -0 $(cat " + d + "/pid) 2>/dev/null && echo alive || echo gone"), "gone\n");
}

TEST(StreamTools, ALoadTestAgainstAServerThatNeverAnswersFailsAndEndsAtTheDeadline) {
  // The connect timeout (10 s) is longer than the run: the deadline
  // (duration 1 s + grace 2 s) must end it.
  const StalledLoadTest run(StallingServer::Behaviour::Silent, 3, 1.0, 2.0,
                            "--connect-timeout 10 --json");
  const TimedRun& t = run.t;
  EXPECT_NE(t.run.err.find("vistream-loadtest: error: 3 of 3 clients failed"), std::string::npos)
      << t.run.err;
  ASSERT_NO_FATAL_FAILURE(run.expectNoClientLoaded(3, "cut_off"));
  const auto& j = t.json;
  EXPECT_EQ(j["clients_not_loaded"], 3);
  EXPECT_EQ(j["clients_cut_off"], 3);
  EXPECT_EQ(j["cut_off_clients"], nlohmann::json({0, 1, 2}));
  EXPECT_EQ(j["grace_s"], 2.0);
  EXPECT_EQ(j["first_error"], "cut off at the deadline while waiting for the Welcome");
  ASSERT_EQ(j["failed_clients"].size(), 3u);
  EXPECT_EQ(j["failed_clients"][2]["client"], 2);
  EXPECT_EQ(j["failed_clients"][2]["reason"], "cut_off");
}

TEST(StreamTools, ALoadTestClientWithoutAWelcomeWithinTheConnectTimeoutFails) {
  const StalledLoadTest run(StallingServer::Behaviour::Silent, 2, 1.0, 5.0,
                            "--connect-timeout 1 --json");
  const TimedRun& t = run.t;
  EXPECT_NE(t.run.err.find("vistream-loadtest: error: "), std::string::npos) << t.run.err;
  ASSERT_NO_FATAL_FAILURE(run.expectNoClientLoaded(2, "handshake"));
  const auto& j = t.json;
  EXPECT_EQ(j["clients_cut_off"], 0);
  EXPECT_EQ(j["first_error"], "no Welcome within 1 s of connecting");
}

TEST(StreamTools, ALoadTestAgainstAServerThatWelcomesAndThenStallsFailsWithNoClientLoaded) {
  const StalledLoadTest run(StallingServer::Behaviour::WelcomeThenSilent, 3, 1.0, 2.0, "--json");
  const TimedRun& t = run.t;
  EXPECT_EQ(run.server.welcomesSent(), 3u);
  EXPECT_NE(t.run.err.find("vistream-loadtest: error: 3 of 3 clients failed (not_loaded 3); 0 of 3 "
                           "got their initial load"),
            std::string::npos)
      << t.run.err;
  ASSERT_NO_FATAL_FAILURE(run.expectNoClientLoaded(3, "not_loaded"));
  const auto& j = t.json;
  EXPECT_EQ(j["clients_not_loaded"], 3);
  EXPECT_EQ(j["clients_cut_off"], 0);
  EXPECT_EQ(j["initial_load_ms"]["count"], 0);
  EXPECT_EQ(j["faces_received"], 0);
}

TEST(StreamTools, ALoadTestThatFailedStillPrintsItsTableOnStdout) {
  const StalledLoadTest run(StallingServer::Behaviour::WelcomeThenSilent, 1, 1.0, 2.0,
                            "--log-level error");
  const TimedRun& t = run.t;
  EXPECT_EQ(t.run.status, 1) << t.run.err;
  EXPECT_NE(t.run.out.find("clients loaded"), std::string::npos) << t.run.out;
  EXPECT_NE(t.run.out.find("0 of 1"), std::string::npos) << t.run.out;
  EXPECT_NE(t.run.out.find("not_loaded"), std::string::npos) << t.run.out;
  EXPECT_EQ(t.run.err.rfind("vistream-loadtest: error: 1 of 1 clients failed", 0), 0u) << t.run.err;
  EXPECT_EQ(t.run.err.find('\n'), t.run.err.size() - 1) << "one line on stderr: " << t.run.err;
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
  vistream::testing::expectFailedSaying(r, 1, "--policy");
  r = runTool("vistream-server", "--scene " + scene.string() + " --fusion maybe");
  vistream::testing::expectFailedSaying(r, 1, "--fusion");
  r = runTool("vistream-server",
              "--scene " + scene.string() + " --token-file " + (dir.path() / "none").string());
  vistream::testing::expectFailedSaying(r, 1, "none");
  r = runTool("vistream-server", "--scene " + scene.string() + " --http-port 70000");
  vistream::testing::expectFailedSaying(r, 1, "--http-port");
  r = runTool("vistream-server",
              "--scene " + scene.string() + " --http-port-file " + (dir.path() / "hp").string());
  vistream::testing::expectFailedSaying(r, 1, "--http-port");
  r = runTool("vistream-server", "--no-such-option");
  EXPECT_EQ(r.status, 2);
  r = runTool("vistream-loadtest", "--clients 2 --path a.csv --paths auto");
  vistream::testing::expectFailedSaying(r, 1, "--path");
  r = runTool("vistream-loadtest",
              "--clients 0 --path " +
                  dir.write("p.csv", "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,0,0,0\n").string());
  vistream::testing::expectFailedSaying(r, 1, "--clients");
  r = runTool("vistream-loadtest", "--grace -1 --path " + (dir.path() / "p.csv").string());
  vistream::testing::expectFailedSaying(r, 1, "--grace");
  r = runTool("vistream-loadtest", "--connect-timeout 0 --path " + (dir.path() / "p.csv").string());
  vistream::testing::expectFailedSaying(r, 1, "--connect-timeout");
}

// CellReady latency counts only what it names: entries that found their cell
// ready are counted apart from those that waited. Without prefetch
// (--prefetch-s 0), 2 m cells and one pose per second at 9 m/s, every pose
// lands about 4 cells past the last one, beyond the neighbours the server
// prepares around a client (stream_scheduler.h), so some entries must wait.
TEST(StreamTools, ALoadTestReportsCellEntriesFoundReadyApartFromThoseThatWaited) {
  vistream::testing::TempDir dir;
  const fs::path scene = dir.write("street.obj", streetObj());
  const fs::path path =
      dir.write("walk.csv", "t,x,y,z,yaw_deg,pitch_deg\n0,0,1.7,30,0,0\n20,0,1.7,-30,0,0\n");
  const std::string bin = VISTREAM_BIN_DIR;
  const std::string d = dir.path().string();
  const std::string loadtest = bin + "/vistream-loadtest --port $(cat " + d +
                               "/port) --clients 2 --path " + path.string() +
                               " --duration 4 --speed 3 --fps 1 --log-level warn";
  sh(bin + "/vistream-server --scene " + scene.string() + " --port 0 --port-file " + d +
     "/port --prefetch-s 0 --cell-size 2 --log-level warn > " + d +
     "/server.log 2>&1 & echo $! > " + d + "/pid; for i in $(seq 1 200); do [ -s " + d +
     "/port ] && break; sleep 0.1; done; " + loadtest + " --json > " + d + "/out.json; " +
     loadtest + " > " + d + "/table.txt; kill -TERM $(cat " + d + "/pid); wait $(cat " + d +
     "/pid) 2>/dev/null");
  std::ifstream out(dir.path() / "out.json");
  const auto j = nlohmann::json::parse(out, nullptr, false);
  ASSERT_FALSE(j.is_discarded());
  EXPECT_EQ(j["errors"], 0) << j.dump();
  const uint64_t entries = j["cell_entries"], ready = j["cell_entries_ready"],
                 waited = j["cell_entries_waited"];
  EXPECT_EQ(ready + waited, entries);
  EXPECT_GE(waited, 1u) << j.dump();
  // Waits: one per entry that waited (a re-entry into a cell still awaited
  // joins the first entry's wait), each strictly positive.
  const auto& wait = j["cell_ready_wait_ms"];
  const uint64_t waits = wait["count"];
  EXPECT_GE(waits, 1u);
  EXPECT_LE(waits, waited);
  ASSERT_FALSE(wait["p50"].is_null());
  EXPECT_GT(wait["p50"].get<double>(), 0.0);
  EXPECT_LE(wait["p50"].get<double>(), wait["max"].get<double>());
  // The old key keeps its meaning: every entry, those found ready as 0 ms.
  const auto& all = j["cell_ready_latency_ms"];
  EXPECT_EQ(all["count"].get<uint64_t>(), ready + waits);
  EXPECT_EQ(all["max"].get<double>(), wait["max"].get<double>());
  std::ifstream tableFile(dir.path() / "table.txt");
  const std::string table((std::istreambuf_iterator<char>(tableFile)), {});
  EXPECT_NE(table.find("found the cell ready"), std::string::npos) << table;
  EXPECT_NE(table.find("CellReady wait ms (p50/p95/p99)"), std::string::npos) << table;
}

// Bad input and first use (issue 12). A scene that does not exist shows that
// the option was checked before the scene was opened: the error names the
// option, not the file.
TEST(StreamTools, OutOfRangeNumbersAndAnAddressThatCannotBeUsedFailBeforeTheSceneLoads) {
  using vistream::testing::expectEachOptionNamed;
  using vistream::testing::expectEachRefused;
  const std::string missing = "/nonexistent/scene.obj";
  const vistream::testing::RefusedCommand server{.tool = "vistream-server",
                                                 .common = "--scene " + missing,
                                                 .at = vistream::testing::MentionAt::Anywhere,
                                                 .unopened = missing};
  expectEachOptionNamed(server, {"--port -1", "--threads -1", "--cell-size -4", "--radius 0",
                                 "--max-speed -3", "--unculled-after -1"});
  const vistream::testing::BadArguments serverSpecific[] = {
      {"--port 99999", "--port: must be an integer in 0..65535"},
      // 192.0.2.1 (TEST-NET-1, RFC 5737) is no address of this machine.
      {"--bind 192.0.2.1 --port 0", "--bind 192.0.2.1"},
      {"--bind not-an-address", "--bind not-an-address"},
  };
  expectEachRefused(server, serverSpecific);
  auto loadtest = server;
  loadtest.tool = "vistream-loadtest";
  loadtest.common = "--paths auto --scene " + missing;
  expectEachOptionNamed(loadtest,
                        {"--clients 0", "--duration -2", "--speed -1", "--fps 0", "--threads 0"});
  const vistream::testing::BadArguments loadtestSpecific[] = {
      {"--clients -1", "--clients: must be an integer >= 1"},
      {"--port 99999", "--port: must be an integer in 1..65535"},
      {"--host no-such-host.invalid", "--host no-such-host.invalid"},
  };
  expectEachRefused(loadtest, loadtestSpecific);
}

TEST(StreamTools, AServerWithoutADatabaseSaysPvssAreComputedOnDemandAndHowToBake) {
  // The advice comes before the scene loads, so a missing scene still shows it.
  const ToolRun r = runTool("vistream-server", "--scene /nonexistent/scene.obj --port 0");
  vistream::testing::expectFailedSaying(r, 1, "no --pvs-db");
  EXPECT_NE(r.err.find("computed on demand"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("vistream-pvs bake --scene /nonexistent/scene.obj"), std::string::npos)
      << r.err;
}

TEST(StreamTools, HelpShowsDefaultsCapturedFromTheCodeNotTypedByHand) {
  for (const char* tool : {"vistream-server", "vistream-loadtest"})
    vistream::testing::expectHelpShowsCapturedDefaults(tool, "=7070");
}

}  // namespace
