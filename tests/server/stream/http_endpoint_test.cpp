// The server's HTTP port (server/stream/http_endpoint.h): health, metrics in
// the Prometheus text format, the PVS as JSON checked against the database
// it is read from, and bad requests answered without disturbing anyone.
#include <gtest/gtest.h>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>

#include "common/world/static_world.h"
#include "server/visibility/pvs_bake.h"
#include "tests/common/support/temp_dir.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
using testing::ServerFixture;
using testing::TestClient;

struct Answer {
  int status = 0;
  std::string body;
};

Answer httpRequest(uint16_t port, const std::string& target, http::verb verb = http::verb::get) {
  boost::asio::io_context io;
  beast::tcp_stream stream(io);
  stream.connect({boost::asio::ip::make_address("127.0.0.1"), port});
  http::request<http::string_body> req(verb, target, 11);
  req.set(http::field::host, "127.0.0.1");
  http::write(stream, req);
  beast::flat_buffer buffer;
  http::response<http::string_body> res;
  http::read(stream, buffer, res);
  return {int(res.result_int()), res.body()};
}

// Sends raw bytes and returns whatever comes back before the server closes
// (or 3 s pass).
std::string rawExchange(uint16_t port, const std::string& bytes) {
  boost::asio::io_context io;
  beast::tcp_stream stream(io);
  stream.connect({boost::asio::ip::make_address("127.0.0.1"), port});
  boost::asio::write(stream.socket(), boost::asio::buffer(bytes));
  stream.expires_after(std::chrono::seconds(3));
  std::string out;
  char chunk[4096];
  beast::error_code ec;
  for (;;) {
    const size_t n = stream.read_some(boost::asio::buffer(chunk), ec);
    out.append(chunk, n);
    if (ec) break;
  }
  return out;
}

StreamServerConfig withHttp() {
  return testing::configWith([](StreamServerConfig& c) { c.httpPort = 0; });
}

TEST(HttpEndpoint, HealthAndMetricsSpeakTheirFormats) {
  ServerFixture fx(withHttp());
  const uint16_t port = fx.server().httpPort();
  ASSERT_NE(port, 0);
  const Answer health = httpRequest(port, "/healthz");
  EXPECT_EQ(health.status, 200);
  EXPECT_EQ(health.body, "ok\n");

  TestClient client(fx.port());
  ASSERT_TRUE(client.join());
  client.pose({0.0, 1.7, 10.0});
  ASSERT_TRUE(client.nextOf(wire::Payload::CellReady, 10.0));
  const Answer metrics = httpRequest(port, "/metrics");
  ASSERT_EQ(metrics.status, 200);
  // Every sample line: a metric name, optional labels, a number.
  const std::regex sample(R"(^[a-z_]+(\{[a-z_]+="[^"]*"\})? [-+0-9.e]+(inf)?$)");
  std::istringstream lines(metrics.body);
  std::map<std::string, double> value;
  std::vector<std::pair<std::string, double>> buckets;
  size_t samples = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("# HELP ", 0) == 0 || line.rfind("# TYPE ", 0) == 0) continue;
    EXPECT_TRUE(std::regex_match(line, sample)) << line;
    ++samples;
    const size_t space = line.rfind(' ');
    value[line.substr(0, space)] = std::stod(line.substr(space + 1));
    if (line.rfind("vistream_cell_face_set_seconds_bucket", 0) == 0)
      buckets.emplace_back(line.substr(0, space), std::stod(line.substr(space + 1)));
  }
  EXPECT_GT(samples, 20u);
  EXPECT_EQ(value["vistream_sessions"], 1.0);
  EXPECT_EQ(value["vistream_sessions_accepted_total"], 1.0);
  EXPECT_GT(value["vistream_bytes_sent_total"], 0.0);
  // The client's cell was answered, so the face-set histogram counted it;
  // buckets are cumulative and +Inf holds the count.
  ASSERT_EQ(buckets.size(), 12u);
  for (size_t b = 1; b < buckets.size(); ++b) EXPECT_GE(buckets[b].second, buckets[b - 1].second);
  EXPECT_EQ(buckets.back().first, "vistream_cell_face_set_seconds_bucket{le=\"+Inf\"}");
  EXPECT_EQ(buckets.back().second, value["vistream_cell_face_set_seconds_count"]);
  EXPECT_GE(value["vistream_cell_face_set_seconds_count"], 1.0);
}

TEST(HttpEndpoint, PvsAnswersWhatTheDatabaseHolds) {
  testing::TempDir dir;
  const Scene scene = testing::streetScene();
  BakeOptions bake;
  bake.cellSize = glm::vec3(8.0f, 4.0f, 8.0f);
  const std::filesystem::path db = dir / "street.pvsdb";
  bakePvs(scene, EpsilonPvs(scene), buildStaticWorld(scene, {}).freeSpace, bake, db);
  const PvsDatabase pvs = PvsDatabase::open(db);
  ASSERT_GT(pvs.cellCount(), 3u);
  StreamWorldOptions wo;
  wo.pvsDatabase = db;
  ServerFixture fx(withHttp(), scene, wo);
  const uint16_t port = fx.server().httpPort();
  const ViewCellGrid grid = pvs.header().grid();
  for (uint32_t c : pvs.cellIndices()) {
    const glm::ivec3 ijk = grid.cellAt(c);
    const Answer a = httpRequest(port, fmt::format("/pvs?cell={},{},{}", ijk.x, ijk.y, ijk.z));
    ASSERT_EQ(a.status, 200) << a.body;
    const nlohmann::json j = nlohmann::json::parse(a.body);
    EXPECT_EQ(j["faces"].get<std::vector<uint32_t>>(), *pvs.cell(c)) << c;
    EXPECT_EQ(j["count"].get<size_t>(), pvs.cell(c)->size());
    // The same cell by a point inside it, in file coordinates (the comma
    // percent-encoded, as some clients send it).
    const glm::dvec3 p = scene.toFile(grid.cellBox(ijk).center());
    const Answer byPoint = httpRequest(port, fmt::format("/pvs?point={}%2C{}%2C{}", p.x, p.y, p.z));
    ASSERT_EQ(byPoint.status, 200) << byPoint.body;
    const nlohmann::json k = nlohmann::json::parse(byPoint.body);
    EXPECT_EQ(k["cell"].get<std::vector<int>>(), (std::vector<int>{ijk.x, ijk.y, ijk.z}));
    EXPECT_EQ(k["faces"], j["faces"]);
  }
}

TEST(HttpEndpoint, BadRequestsGetAStatusAndTheStreamKeepsServing) {
  ServerFixture fx(withHttp());
  const uint16_t port = fx.server().httpPort();
  const std::pair<std::string, int> cases[] = {
      {"/pvs?point=1,2", 400},
      {"/pvs?point=a,b,c", 400},
      {"/pvs?cell=1.5,0,0", 400},
      {"/pvs", 400},
      {"/pvs?point=1,2,3&cell=0,0,0", 400},
      {"/pvs?cell=99999,0,0", 404},
      {"/pvs?point=1e9,0,0", 404},
      {"/nowhere", 404},
  };
  for (const auto& [target, status] : cases) {
    const Answer a = httpRequest(port, target);
    EXPECT_EQ(a.status, status) << target << ": " << a.body;
    EXPECT_FALSE(a.body.empty()) << target;
  }
  EXPECT_EQ(httpRequest(port, "/pvs?cell=0,0,0", http::verb::post).status, 405);
  EXPECT_NE(httpRequest(port, "/pvs?point=1,2").body.find("point"), std::string::npos);
  // Garbage and an oversized header: a 400 or a closed connection, nothing else.
  EXPECT_NE(rawExchange(port, "GARBAGE\r\n\r\n").find("400"), std::string::npos);
  const std::string huge =
      "GET /healthz HTTP/1.1\r\nX-Filler: " + std::string(20000, 'x') + "\r\n\r\n";
  const std::string hugeAnswer = rawExchange(port, huge);
  EXPECT_TRUE(hugeAnswer.empty() || hugeAnswer.find("400") != std::string::npos) << hugeAnswer;
  // Everyone else is still served.
  EXPECT_EQ(httpRequest(port, "/healthz").status, 200);
  TestClient client(fx.port());
  EXPECT_TRUE(client.join());
}

}  // namespace
}  // namespace vistream
