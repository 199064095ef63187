// Hostile clients over real loopback sockets: what one client can make the
// server do is bounded, and honest clients keep being served.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <atomic>

#include "tests/common/support/captured_log.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

using namespace std::chrono_literals;

std::string errorText(const std::vector<uint8_t>& frame) {
  const auto* e = wire::envelopeOf(frame)->payload_as_Error();
  return e && e->text() ? e->text()->str() : std::string();
}

// The Error frame's code and text within the timeout, or nothing.
std::optional<std::pair<wire::ErrorCode, std::string>> nextError(TestClient& c,
                                                                 double timeoutS = 5.0) {
  const auto f = c.nextOf(wire::Payload::Error, timeoutS);
  if (!f) return std::nullopt;
  return std::make_pair(wire::envelopeOf(*f)->payload_as_Error()->code(), errorText(*f));
}

// Expects the next Error frame within the timeout to carry `code` and a text
// naming `what`. Fatal if none comes: call it in ASSERT_NO_FATAL_FAILURE.
void expectErrorNaming(TestClient& c, wire::ErrorCode code, const std::string& what,
                       double timeoutS = 5.0) {
  const auto e = nextError(c, timeoutS);
  ASSERT_TRUE(e) << "no Error naming " << what;
  EXPECT_EQ(e->first, code);
  EXPECT_NE(e->second.find(what), std::string::npos) << e->second;
}

const glm::dvec3 kStreetPoint{0.0, 1.7, 8.0};

TEST(HostileClient, AnAbsurdVelocityIsRefusedNamingTheFieldAndNoThreadHangs) {
  ServerFixture server;
  // Two sessions, one per I/O thread, each with a velocity whose length is
  // infinite in float (the prefetch loop once never ended).
  TestClient a(server.port()), b(server.port());
  for (TestClient* c : {&a, &b}) {
    c->hello();
    ASSERT_TRUE(c->nextOf(wire::Payload::Welcome));
    c->pose(kStreetPoint, 0.0f, glm::vec3(1e30f, 0.0f, 1e30f));
  }
  for (TestClient* c : {&a, &b}) {
    ASSERT_NO_FATAL_FAILURE(expectErrorNaming(*c, wire::ErrorCode::BadRequest, "Pose.velocity"));
    EXPECT_TRUE(c->closedWithin(5.0));
  }
  EXPECT_TRUE(honestClientLoads(server.port(), kStreetPoint, 10.0));
}

TEST(HostileClient, APlausibleSpeedWithAHugePrefetchHorizonStaysBounded) {
  // The prefetch horizon is prefetch-s times the speed: with 1e9 s the old
  // loop took 1e11 steps on the I/O thread. Now it samples a fixed number.
  ServerFixture server(configWith([](StreamServerConfig& c) { c.prefetchSeconds = 1e9; }));
  TestClient fast(server.port());
  ASSERT_TRUE(fast.join());
  fast.pose(kStreetPoint, 0.0f, glm::vec3(90.0f, 0.0f, 0.0f));
  EXPECT_TRUE(fast.nextOf(wire::Payload::CellReady, 10.0));
  EXPECT_TRUE(honestClientLoads(server.port(), kStreetPoint, 10.0));
}

TEST(HostileClient, AVelocityJustOverTheLimitIsRefusedAndJustUnderIsServed) {
  ServerFixture server(configWith([](StreamServerConfig& c) { c.maxSpeedMps = 50.0; }));
  TestClient over(server.port()), under(server.port());
  ASSERT_TRUE(over.join());
  ASSERT_TRUE(under.join());
  over.pose(kStreetPoint, 0.0f, glm::vec3(30.0f, 0.0f, 40.5f));   // 50.3 m/s
  under.pose(kStreetPoint, 0.0f, glm::vec3(30.0f, 0.0f, 39.5f));  // 49.6 m/s
  ASSERT_NO_FATAL_FAILURE(expectErrorNaming(over, wire::ErrorCode::BadRequest, "Pose.velocity"));
  EXPECT_TRUE(under.nextOf(wire::Payload::CellReady, 10.0));
}

TEST(HostileClient, APoseFarOutsideTheSceneIsRefusedNamingThePosition) {
  // The street scene spans -30..30 m.
  ServerFixture server(configWith([](StreamServerConfig& c) { c.poseMarginM = 100.0; }));
  TestClient far(server.port()), near(server.port());
  ASSERT_TRUE(far.join());
  ASSERT_TRUE(near.join());
  far.pose({0.0, 1.7, 131.0});   // 101 m beyond the far edge
  near.pose({0.0, 1.7, 129.0});  // 99 m beyond it: allowed (clamped to the grid)
  ASSERT_NO_FATAL_FAILURE(expectErrorNaming(far, wire::ErrorCode::BadRequest, "Pose.position"));
  EXPECT_FALSE(near.nextOf(wire::Payload::Error, 1.0));
}

TEST(HostileClient, PvsRequestsBeyondTheWaitingLimitAreRateLimitedAndPipelinedOnesAreAnswered) {
  ServerFixture server(configWith([](StreamServerConfig& c) { c.maxPvsRequestsWaiting = 8; }));
  const ViewCellGrid& g = server.world().grid();
  auto request = [&](uint32_t id) {
    wire::PvsRequestT q;
    q.request_id = id;
    q.by_cell = true;
    q.cell = std::make_unique<wire::CellIndex>(
        wire::toWire(glm::ivec3(int(id) % g.dims().x, 0, int(id) / g.dims().x % g.dims().z)));
    return wire::encodeMessage(std::move(q));
  };
  TestClient polite(server.port());
  ASSERT_TRUE(polite.join());
  for (uint32_t id = 0; id < 8; ++id) polite.sendRaw(request(id));
  std::set<uint32_t> answered;
  for (int i = 0; i < 8; ++i) {
    const auto f = polite.nextOf(wire::Payload::PvsReply, 10.0);
    ASSERT_TRUE(f);
    answered.insert(wire::envelopeOf(*f)->payload_as_PvsReply()->request_id());
  }
  EXPECT_EQ(answered.size(), 8u);

  TestClient greedy(server.port());
  ASSERT_TRUE(greedy.join());
  std::vector<uint8_t> burst;
  for (uint32_t id = 0; id < 200; ++id) {
    const auto f = request(id);
    burst.insert(burst.end(), f.begin(), f.end());
  }
  greedy.sendRaw(burst);
  ASSERT_NO_FATAL_FAILURE(
      expectErrorNaming(greedy, wire::ErrorCode::RateLimited, "PvsRequest", 10.0));
}

TEST(HostileClient, AFrameTrickledOneByteAtATimeTimesOut) {
  ServerFixture server(configWith([](StreamServerConfig& c) {
    c.frameTimeoutS = 1.0;
    c.idleTimeoutS = 60.0;
  }));
  TestClient slow(server.port());
  ASSERT_TRUE(slow.join());
  // A Pose frame, one byte every 300 ms: each byte once reset the idle timer.
  wire::PoseT m;
  m.position = std::make_unique<wire::Vec3d>(wire::toWire(kStreetPoint));
  const auto frame = wire::encodeMessage(std::move(m));
  std::optional<std::pair<wire::ErrorCode, std::string>> e;
  for (size_t i = 0; i < frame.size() && !e; ++i) {
    boost::system::error_code ec;
    boost::asio::write(slow.socket(), boost::asio::buffer(&frame[i], 1), ec);
    if (ec) break;
    e = nextError(slow, 0.3);
  }
  ASSERT_TRUE(e);
  EXPECT_EQ(e->first, wire::ErrorCode::Timeout);
  EXPECT_NE(e->second.find("frame"), std::string::npos) << e->second;
  EXPECT_TRUE(slow.closedWithin(5.0));
}

TEST(HostileClient, SessionsFromOneAddressAreLimitedWhenAsked) {
  ServerFixture server(configWith([](StreamServerConfig& c) { c.maxClientsPerAddress = 2; }));
  auto a = std::make_unique<TestClient>(server.port());
  TestClient b(server.port());
  a->hello();
  b.hello();
  ASSERT_TRUE(a->nextOf(wire::Payload::Welcome));
  ASSERT_TRUE(b.nextOf(wire::Payload::Welcome));
  TestClient c(server.port());
  ASSERT_NO_FATAL_FAILURE(expectErrorNaming(c, wire::ErrorCode::TooManyClients, "one address"));
  // A slot freed is a slot again.
  a.reset();
  for (int attempt = 0; attempt < 50; ++attempt) {
    TestClient d(server.port());
    d.hello();
    const auto f = d.next(2.0);
    ASSERT_TRUE(f);
    if (wire::envelopeOf(*f)->payload_type() == wire::Payload::Welcome) return;
    std::this_thread::sleep_for(100ms);  // the server has not seen the close yet
  }
  ADD_FAILURE() << "no Welcome after a session from the address ended";
}

TEST(HostileClient, ConnectionChurnDoesNotFloodTheLog) {
  CapturedLog log;
  ServerFixture server;
  // 300 sessions that each break the protocol: each once logged a warning.
  for (int i = 0; i < 300; ++i) {
    TestClient c(server.port());
    c.sendRaw({0x08, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8});  // an unverifiable frame
    c.closedWithin(2.0);
  }
  std::this_thread::sleep_for(200ms);
  EXPECT_LE(log.warningCount(), 25u) << "warnings logged for 300 bad sessions";
  EXPECT_GT(server.server().peerWarnings().suppressed(), 250u);
}

TEST(HostileClient, AMaximumBeyondTheOpenFileLimitIsLoweredToFitIt) {
  rlimit limit{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &limit), 0);
  StreamServerConfig cfg;
  if (limit.rlim_max == RLIM_INFINITY) {
    // Without a hard limit the soft one is raised to fit whatever is asked.
    cfg.maxClients = 2 * size_t(limit.rlim_cur) + 1000;
    ServerFixture server(cfg);
    EXPECT_EQ(server.server().maxClients(), cfg.maxClients);
    rlimit now{};
    getrlimit(RLIMIT_NOFILE, &now);
    EXPECT_GE(now.rlim_cur, rlim_t(cfg.maxClients));
  } else {
    cfg.maxClients = size_t(limit.rlim_max) + 1000;
    ServerFixture server(cfg);
    EXPECT_LT(server.server().maxClients(), size_t(limit.rlim_max));
    EXPECT_GT(server.server().maxClients(), 0u);
    rlimit now{};
    getrlimit(RLIMIT_NOFILE, &now);
    EXPECT_EQ(now.rlim_cur, limit.rlim_max);  // the soft limit was raised as far as it goes
  }
  setrlimit(RLIMIT_NOFILE, &limit);
}

TEST(HostileClient, AnUnknownPayloadTypeIsCalledUnknown) {
  ServerFixture server;
  TestClient c(server.port());
  ASSERT_TRUE(c.join());
  // An Envelope whose payload type is beyond the schema's union, carrying a table.
  flatbuffers::FlatBufferBuilder b;
  const auto bye = wire::CreateByeDirect(b, "x");
  wire::EnvelopeBuilder eb(b);
  eb.add_payload_type(wire::Payload(200));
  eb.add_payload(bye.Union());
  b.Finish(eb.Finish());
  c.sendRaw(wire::encodeFrame(b));
  const auto e = nextError(c);
  ASSERT_TRUE(e);
  EXPECT_NE(e->second.find("unknown payload type 200"), std::string::npos) << e->second;
}

TEST(HostileClient, AnOversizedFrameIsFrameTooLargeWhereverItStartsInARead) {
  ServerFixture server(configWith([](StreamServerConfig& c) { c.maxInboundFrameBytes = 1024; }));
  const std::vector<uint8_t> oversized{0x00, 0x10, 0x00, 0x00};  // 4096 bytes announced
  // Alone, and after a whole Hello in the same write (the length is then
  // read by next(), not by feed()).
  for (bool afterHello : {false, true}) {
    TestClient c(server.port());
    std::vector<uint8_t> bytes;
    if (afterHello) bytes = wire::encodeHello(wire::kProtocolVersion, "");
    bytes.insert(bytes.end(), oversized.begin(), oversized.end());
    c.sendRaw(bytes);
    const auto e = nextError(c);
    ASSERT_TRUE(e) << afterHello;
    EXPECT_EQ(e->first, wire::ErrorCode::FrameTooLarge) << afterHello << ": " << e->second;
  }
}

}  // namespace
}  // namespace vistream::testing
