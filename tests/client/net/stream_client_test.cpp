// StreamClient against scripted servers: whatever a server sends, the client
// ends the session with a message naming the problem, never crashes, and
// never holds more than its limit.
#include "client/net/stream_client.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <boost/asio.hpp>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>  // before Boost.Asio

#include "common/core/error.h"
#include "protocol/geometry/byte_coding.h"
#include "protocol/geometry/geometry_codec.h"
#include "protocol/impostor/impostor_message.h"
#include "protocol/wire/messages.h"

namespace vistream {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;
using namespace vistream::wire;

// A server on a loopback port that, once a client connects, sends `frames`
// and then keeps the connection open until the client closes it.
class ScriptedServer {
 public:
  explicit ScriptedServer(std::vector<std::vector<uint8_t>> frames)
      : acceptor_(io_, {asio::ip::make_address("127.0.0.1"), 0}) {
    port_ = acceptor_.local_endpoint().port();
    thread_ = std::thread([this, frames = std::move(frames)] {
      tcp::socket s(io_);
      boost::system::error_code ec;
      acceptor_.accept(s, ec);
      if (ec) return;
      for (const auto& f : frames) asio::write(s, asio::buffer(f), ec);
      std::array<uint8_t, 4096> buf;
      while (!ec) s.read_some(asio::buffer(buf), ec);  // until the client leaves
    });
  }
  ~ScriptedServer() { thread_.join(); }
  uint16_t port() const { return port_; }

 private:
  asio::io_context io_;
  tcp::acceptor acceptor_;
  uint16_t port_ = 0;
  std::thread thread_;
};

WelcomeT goodWelcome() {
  WelcomeT w;
  w.protocol_version = kProtocolVersion;
  w.local_origin = std::make_unique<Vec3d>(0.0, 0.0, 0.0);
  w.grid = std::make_unique<CellGridT>();
  w.grid->origin = std::make_unique<Vec3f>(0.0f, 0.0f, 0.0f);
  w.grid->cell_size = std::make_unique<Vec3f>(4.0f, 4.0f, 4.0f);
  w.grid->dims = std::make_unique<CellIndex>(10, 2, 10);
  w.near_field_radius_m = 100.0f;
  w.quant_origin = std::make_unique<Vec3d>(0.0, 0.0, 0.0);  // QuantizationGrid{}'s
  w.quant_step = QuantizationGrid{}.step;
  return w;
}

StreamClientOptions to(const ScriptedServer& server) {
  StreamClientOptions o;
  o.port = server.port();
  o.timeoutS = 5.0;
  return o;
}

std::string errorOfConnecting(const StreamClientOptions& o) {
  try {
    StreamClient c(o);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(StreamClient, RefusesAWelcomeWithAZeroCellSize) {
  WelcomeT w = goodWelcome();
  w.grid->cell_size = std::make_unique<Vec3f>(4.0f, 0.0f, 4.0f);
  ScriptedServer server({encodeMessage(std::move(w))});
  EXPECT_NE(errorOfConnecting(to(server)).find("no usable grid"), std::string::npos);
}

TEST(StreamClient, RefusesAFrameThatNamesAPayloadButCarriesNone) {
  flatbuffers::FlatBufferBuilder b;
  EnvelopeBuilder e(b);
  e.add_payload_type(Payload::Welcome);
  b.Finish(e.Finish());
  ScriptedServer server({encodeFrame(b)});
  EXPECT_NE(errorOfConnecting(to(server)).find("carries none"), std::string::npos);
}

TEST(StreamClient, EndsTheSessionWhenTheServerSendsMoreTrianglesThanItsLimit) {
  std::vector<FaceTriangles> faces;
  for (uint32_t f = 0; f < 20; ++f)
    faces.push_back({f, 0, {{float(f), 0, 0}, {float(f) + 1, 0, 0}, {float(f), 1, 0}}, {}, {}});
  ScriptedServer server(
      {encodeMessage(goodWelcome()), encodeMessage(encodeGeometry(faces, QuantizationGrid{}))});
  StreamClientOptions o = to(server);
  o.maxTriangles = 10;
  StreamClient client(o);
  for (int i = 0; i < 200 && client.error().empty(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_NE(client.error().find("more than 10 triangles"), std::string::npos) << client.error();
  client.sendPose({0, 1.7f, 0}, 0, 0);  // dropped, not queued forever
}

TEST(StreamClient, HoldsWhatAWellBehavedServerSends) {
  std::vector<FaceTriangles> faces;
  for (uint32_t f = 0; f < 5; ++f)
    faces.push_back({f, 0, {{float(f), 0, 0}, {float(f) + 1, 0, 0}, {float(f), 1, 0}}, {}, {}});
  ScriptedServer server(
      {encodeMessage(goodWelcome()), encodeMessage(encodeGeometry(faces, QuantizationGrid{}))});
  StreamClient client(to(server));
  for (int i = 0; i < 200 && client.facesHeld() < 5; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(client.facesHeld(), 5u);
  const RenderGeometry g = client.snapshot();
  EXPECT_EQ(g.size(), 5u);
  EXPECT_TRUE(client.error().empty()) << client.error();
}

// A view cell of merged grid cells (ImpostorData.cell_hi): the client
// keeps its impostors for every cell of the run and none beyond it, and
// ends the session when the run leaves the grid.
TEST(StreamClient, KeepsAViewCellsImpostorsForEveryCellOfItsRun) {
  WelcomeT w = goodWelcome();
  w.impostors = true;
  ImpostorMessage m;
  m.cell = {2, 0, 3};
  m.cellHi = glm::ivec3(2, 0, 6);
  m.why = "far field lighter than the threshold";
  ScriptedServer server({encodeMessage(std::move(w)), encodeImpostorMessage(m)});
  StreamClientOptions o = to(server);
  o.wantsImpostors = true;
  StreamClient client(o);
  const glm::vec3 inFirst(10.0f, 1.0f, 14.0f), inLast(10.0f, 1.0f, 26.0f);
  for (int i = 0; i < 200 && !client.impostorsAt(inFirst); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto set = client.impostorsAt(inFirst);
  ASSERT_TRUE(set) << client.error();
  EXPECT_EQ(client.impostorsAt(inLast), set);
  EXPECT_EQ(set->cell.lo, glm::vec3(8.0f, 0.0f, 12.0f));
  EXPECT_EQ(set->cell.hi, glm::vec3(12.0f, 4.0f, 28.0f));
  EXPECT_EQ(set->why, m.why);
  EXPECT_FALSE(client.impostorsAt({10.0f, 1.0f, 30.0f}));  // cell (2, 0, 7)
  EXPECT_FALSE(client.impostorsAt({14.0f, 1.0f, 14.0f}));  // cell (3, 0, 3)
  EXPECT_TRUE(client.error().empty()) << client.error();

  WelcomeT w2 = goodWelcome();
  w2.impostors = true;
  m.cellHi = glm::ivec3(2, 0, 10);  // the grid has 10 cells along z
  ScriptedServer beyond({encodeMessage(std::move(w2)), encodeImpostorMessage(m)});
  StreamClientOptions o2 = to(beyond);
  o2.wantsImpostors = true;
  StreamClient refused(o2);
  for (int i = 0; i < 200 && refused.error().empty(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_NE(refused.error().find("outside the grid"), std::string::npos) << refused.error();
}

}  // namespace
}  // namespace vistream

namespace vistream {
namespace {

// Welcome.ground_y reaches the renderer's geometry only when the server says
// a plane is assumed and the height is a finite number.
TEST(StreamClient, TakesTheAssumedGroundPlaneFromTheWelcome) {
  struct Case {
    const char* name;
    bool hasGround;
    float groundY;
    std::optional<float> expected;
  };
  for (const Case& k :
       {Case{"assumed", true, -3.5f, -3.5f}, Case{"not assumed", false, -3.5f, std::nullopt},
        Case{"not finite", true, std::numeric_limits<float>::quiet_NaN(), std::nullopt}}) {
    SCOPED_TRACE(k.name);
    WelcomeT w = goodWelcome();
    w.has_ground = k.hasGround;
    w.ground_y = k.groundY;
    ScriptedServer server({encodeMessage(std::move(w))});
    StreamClient client(to(server));
    EXPECT_EQ(client.snapshot().groundY, k.expected);
  }
}

// The faces of a geometry as (face ID, corners) pairs, in a canonical order.
std::vector<std::pair<uint32_t, std::array<float, 9>>> facesIn(const RenderGeometry& g) {
  std::vector<std::pair<uint32_t, std::array<float, 9>>> out;
  for (size_t t = 0; t < g.size(); ++t) {
    std::array<float, 9> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[size_t(3 * k + a)] = g.triangles.vertex(t, k)[a];
    out.push_back({g.triangles.faceIds[t], c});
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(StreamClient, DeltasTakenUpInTurnHoldWhatTheSnapshotHolds) {
  auto face = [](uint32_t f, float y) {
    return FaceTriangles{
        f, 0, {{float(f), y, 0}, {float(f) + 1, y, 0}, {float(f), y + 1, 0}}, {}, {}};
  };
  std::vector<FaceTriangles> first;
  for (uint32_t f = 0; f < 10; ++f) first.push_back(face(f, 0.0f));
  ScriptedServer server(
      {encodeMessage(goodWelcome()), encodeMessage(encodeGeometry(first, QuantizationGrid{}))});
  StreamClient client(to(server));
  for (int i = 0; i < 300 && client.facesHeld() < 10; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_EQ(client.facesHeld(), 10u) << client.error();
  StreamedGeometry held;
  const GeometryDelta all = client.takeDelta();
  EXPECT_TRUE(all.replaceAll) << "the first delta carries everything";
  held.apply(all);
  EXPECT_EQ(facesIn(held.compacted()), facesIn(client.snapshot()));
  const GeometryDelta none = client.takeDelta();
  EXPECT_TRUE(none.removed.empty());
  EXPECT_EQ(none.added.size(), 0u);
}

TEST(StreamClient, DeltasCarryEvictionsAndFacesSentAgain) {
  auto face = [](uint32_t f, float y) {
    return FaceTriangles{
        f, 0, {{float(f), y, 0}, {float(f) + 1, y, 0}, {float(f), y + 1, 0}}, {}, {}};
  };
  std::vector<FaceTriangles> first;
  for (uint32_t f = 0; f < 10; ++f) first.push_back(face(f, 0.0f));
  EvictT evict;
  evict.face_ids = {2, 3, 7, 99};  // 99 never held
  const std::vector<FaceTriangles> second = {face(3, 5.0f), face(4, 6.0f), face(10, 0.0f)};
  ScriptedServer server(
      {encodeMessage(goodWelcome()), encodeMessage(encodeGeometry(first, QuantizationGrid{})),
       encodeMessage(std::move(evict)), encodeMessage(encodeGeometry(second, QuantizationGrid{}))});
  StreamClient client(to(server));
  StreamedGeometry held;
  // Take deltas while the frames arrive, until the client has seen them all
  // (Geometry, Evict, Geometry: three versions).
  for (int i = 0; i < 300 && client.version() < 3; ++i) {
    held.apply(client.takeDelta());
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_GE(client.version(), 3u) << client.error();
  held.apply(client.takeDelta());
  const auto faces = facesIn(held.compacted());
  EXPECT_EQ(faces, facesIn(client.snapshot()));
  // Independently: faces 0-10 but 2 and 7, face 3 at y = 5 and face 4 at y = 6.
  ASSERT_EQ(faces.size(), 9u);
  for (const auto& [id, corners] : faces) {
    EXPECT_NE(id, 2u);
    EXPECT_NE(id, 7u);
    EXPECT_EQ(corners[1], id == 3 ? 5.0f : id == 4 ? 6.0f : 0.0f) << "face " << id;
  }
}

}  // namespace
}  // namespace vistream

namespace vistream {
namespace {

// A server that dies once: the first connection gets `first` and is then
// closed; the second (the client coming back to the same address) has its
// frames recorded, gets `second` after its first frame and stays open until
// the client leaves (it stops waiting after 5 s if none comes back).
class DyingServer {
 public:
  DyingServer(std::vector<std::vector<uint8_t>> first, std::vector<std::vector<uint8_t>> second)
      : acceptor_(io_, {asio::ip::make_address("127.0.0.1"), 0}) {
    port_ = acceptor_.local_endpoint().port();
    thread_ = std::thread([this, first = std::move(first), second = std::move(second)] {
      boost::system::error_code ec;
      {
        tcp::socket s(io_);
        acceptor_.accept(s, ec);
        if (ec) return;
        for (const auto& f : first) asio::write(s, asio::buffer(f), ec);
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      }  // closed: the server died
      // The client may not come back (reconnection off): wait 5 s at most.
      tcp::socket s(io_);
      bool accepted = false;
      acceptor_.async_accept(s, [&](const boost::system::error_code& e) {
        ec = e;
        accepted = true;
      });
      io_.run_for(std::chrono::seconds(5));
      if (!accepted || ec) return;
      FrameDecoder decoder;
      std::array<uint8_t, 4096> buf;
      bool sent = false;
      while (!ec) {
        const size_t n = s.read_some(asio::buffer(buf), ec);
        decoder.feed({buf.data(), n});
        while (auto frame = decoder.next()) {
          std::lock_guard lock(mutex_);
          received_.push_back(*frame);
        }
        if (!sent) {
          for (const auto& f : second) asio::write(s, asio::buffer(f), ec);
          sent = true;
        }
      }
    });
  }
  ~DyingServer() { thread_.join(); }
  uint16_t port() const { return port_; }
  std::vector<std::vector<uint8_t>> received() const {
    std::lock_guard lock(mutex_);
    return received_;
  }

 private:
  asio::io_context io_;
  tcp::acceptor acceptor_;
  uint16_t port_ = 0;
  std::thread thread_;
  mutable std::mutex mutex_;
  std::vector<std::vector<uint8_t>> received_;
};

std::vector<uint8_t> welcomeOf(const std::string& scene, uint32_t faceCount) {
  WelcomeT w = goodWelcome();
  w.scene_id = scene;
  w.face_count = faceCount;
  return encodeMessage(std::move(w));
}

std::vector<uint8_t> geometryOf(uint32_t from, uint32_t to) {
  std::vector<FaceTriangles> faces;
  for (uint32_t f = from; f < to; ++f)
    faces.push_back({f, 0, {{float(f), 0, 0}, {float(f) + 1, 0, 0}, {float(f), 1, 0}}, {}, {}});
  return encodeMessage(encodeGeometry(faces, QuantizationGrid{}));
}

bool waitUntil(const std::function<bool()>& condition) {
  for (int i = 0; i < 500 && !condition(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return condition();
}

TEST(StreamClient, ComesBackAfterTheServerDiesNamingTheFacesItHoldsAndResendingItsPose) {
  DyingServer server({welcomeOf("city", 100), geometryOf(0, 5), geometryOf(10, 13)},
                     {welcomeOf("city", 100), geometryOf(20, 22)});
  StreamClientOptions o;
  o.port = server.port();
  o.timeoutS = 5.0;
  StreamClient client(o);
  ASSERT_TRUE(waitUntil([&] { return client.facesHeld() == 8; }));
  client.sendPose({1.0f, 1.7f, 2.0f}, 90.0f, 0.0f);
  // The server dies; the client comes back and gets the rest.
  EXPECT_TRUE(waitUntil([&] { return client.facesHeld() == 10; })) << client.error();
  EXPECT_TRUE(client.error().empty()) << client.error();
  EXPECT_EQ(client.reconnects(), 1u);
  EXPECT_FALSE(client.reconnecting());
  // What the second server heard: a Hello naming faces 0..4 and 10..12 of
  // the scene, then the last pose again.
  ASSERT_TRUE(waitUntil([&] { return server.received().size() >= 2; }));
  const auto heard = server.received();
  const Hello* hello = envelopeOf(heard[0])->payload_as_Hello();
  ASSERT_NE(hello, nullptr);
  EXPECT_EQ(hello->held_scene_id()->str(), "city");
  EXPECT_EQ(hello->held_face_count(), 100u);
  PayloadReader reader({hello->held_faces()->data(), hello->held_faces()->size()});
  std::vector<uint32_t> held;
  ASSERT_TRUE(readIdRanges(reader, 100, 100, "held", held)) << reader.error();
  EXPECT_EQ(held, (std::vector<uint32_t>{0, 1, 2, 3, 4, 10, 11, 12}));
  const Pose* pose = envelopeOf(heard[1])->payload_as_Pose();
  ASSERT_NE(pose, nullptr) << "the pose was not sent again after the Welcome";
  EXPECT_EQ(pose->yaw_deg(), 90.0f);
}

TEST(StreamClient, ComingBackToAnotherSceneEndsTheSessionSayingSo) {
  DyingServer server({welcomeOf("city", 100), geometryOf(0, 5)},
                     {welcomeOf("village", 40), geometryOf(0, 2)});
  StreamClientOptions o;
  o.port = server.port();
  o.timeoutS = 5.0;
  StreamClient client(o);
  EXPECT_TRUE(waitUntil([&] { return !client.error().empty(); }));
  EXPECT_NE(client.error().find("reconnected to scene 'village'"), std::string::npos)
      << client.error();
}

TEST(StreamClient, WithoutReconnectALostServerEndsTheSession) {
  DyingServer server({welcomeOf("city", 100), geometryOf(0, 5)}, {});
  StreamClientOptions o;
  o.port = server.port();
  o.timeoutS = 5.0;
  o.reconnect = false;
  StreamClient client(o);
  EXPECT_TRUE(waitUntil([&] { return !client.error().empty(); }));
  EXPECT_NE(client.error().find("connection closed"), std::string::npos) << client.error();
  EXPECT_EQ(client.reconnects(), 0u);
  EXPECT_EQ(client.facesHeld(), 5u);  // what arrived stays
}

}  // namespace
}  // namespace vistream
