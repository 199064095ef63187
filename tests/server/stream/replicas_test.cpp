// Serving from replicas (issue 17): a client that reconnects naming the
// faces it holds is sent only what is missing; users on one replica appear
// on the other through Redis (a real redis-server on a free loopback port),
// and a replica that loses Redis keeps serving its own users and rejoins.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <boost/asio/connect.hpp>
#include <chrono>
#include <functional>
#include <set>
#include <thread>

#include "common/core/error.h"
#include "protocol/geometry/byte_coding.h"
#include "server/stream/presence.h"
#include "server/stream/stream_server.h"
#include "tests/server/stream/stream_test_support.h"

namespace vistream {
namespace {

using testing::configWith;
using testing::nextErrorCode;
using testing::Received;
using testing::receiveUntilReady;
using testing::ServerFixture;
using testing::TestClient;
using wire::Payload;

// Poses at `eye` and reads until its cell is ready.
Received loadCell(TestClient& c, ServerFixture& fx, const glm::dvec3& eye) {
  c.pose(eye);
  return receiveUntilReady(c, *fx.world().cellOf(glm::vec3(eye)),
                           wire::QuantizationGrid::forBounds(fx.world().scene().bounds()));
}

// A Hello naming held faces, as a reconnecting client sends it.
void helloHolding(TestClient& c, const std::string& scene, uint32_t faceCount,
                  const std::vector<uint32_t>& held, float radius) {
  wire::HelloT h;
  h.protocol_version = wire::kProtocolVersion;
  h.capabilities = std::make_unique<wire::CapabilitiesT>();
  h.capabilities->near_field_radius_m = radius;
  h.held_scene_id = scene;
  h.held_face_count = faceCount;
  wire::putIdRanges(h.held_faces, held);
  c.sendRaw(wire::encodeMessage(std::move(h)));
}

const glm::dvec3 kEye(0.5, 1.7, 8.5);

// A first client loads the cell of kEye; the faces it got, ascending.
std::vector<uint32_t> firstLoad(ServerFixture& fx) {
  TestClient first(fx.port());
  EXPECT_TRUE(first.join("", wire::kProtocolVersion, 40.0f));
  const Received all = loadCell(first, fx, kEye);
  EXPECT_TRUE(all.ready);
  std::vector<uint32_t> held(all.faces.begin(), all.faces.end());
  std::sort(held.begin(), held.end());
  return held;
}

TEST(Failover, AReconnectingClientNamingItsFacesIsSentOnlyTheRest) {
  ServerFixture fx;
  const std::string scene = fx.world().scene().name;
  const uint32_t faces = fx.world().faceCount();
  // The first session: everything the cell needs.
  const std::vector<uint32_t> held = firstLoad(fx);
  ASSERT_GT(held.size(), 10u);

  // Holding all of it: the cell is ready with no geometry sent.
  TestClient whole(fx.port());
  helloHolding(whole, scene, faces, held, 40.0f);
  ASSERT_TRUE(whole.nextOf(Payload::Welcome));
  const Received none = loadCell(whole, fx, kEye);
  EXPECT_TRUE(none.ready);
  EXPECT_TRUE(none.faces.empty()) << none.faces.size() << " held faces were sent again";

  // Holding every other face: exactly the others arrive, once each.
  std::vector<uint32_t> half, rest;
  for (size_t i = 0; i < held.size(); ++i) (i % 2 ? rest : half).push_back(held[i]);
  TestClient partial(fx.port());
  helloHolding(partial, scene, faces, half, 40.0f);
  ASSERT_TRUE(partial.nextOf(Payload::Welcome));
  Received got = loadCell(partial, fx, kEye);
  EXPECT_TRUE(got.ready);
  std::sort(got.faces.begin(), got.faces.end());
  EXPECT_EQ(std::adjacent_find(got.faces.begin(), got.faces.end()), got.faces.end())
      << "a face was sent twice";
  EXPECT_FALSE(got.faces.empty());
  // Only faces it lacked; with the others it named, the cell is whole (ready).
  EXPECT_TRUE(std::includes(rest.begin(), rest.end(), got.faces.begin(), got.faces.end()));
}

TEST(Failover, FacesHeldFromAnotherSceneAreIgnored) {
  ServerFixture fx;
  const std::vector<uint32_t> held = firstLoad(fx);
  ASSERT_FALSE(held.empty());
  // Without a database a session gets the coarse set first and the cell's
  // own once a worker has refined it; every client below must find the
  // refined set cached, or the first would get the coarse one and a later
  // one the refined one. A client standing in the cell asks for the
  // refinement; wait until it is cached.
  TestClient warm(fx.port());
  ASSERT_TRUE(warm.join("", wire::kProtocolVersion, 40.0f));
  ASSERT_TRUE(loadCell(warm, fx, kEye).ready);
  const glm::ivec3 cell = *fx.world().cellOf(glm::vec3(kEye));
  const StreamServerConfig config;
  const float radius = std::min(40.0f, config.maxRadius);
  for (int k = 0;
       k < 3000 && !fx.world().hasCellFaceSet(cell, CellLevel::Fine, config.policy, radius); ++k)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(fx.world().hasCellFaceSet(cell, CellLevel::Fine, config.policy, radius));
  // What a client holding nothing gets now (the cell's sets are cached).
  TestClient fresh(fx.port());
  ASSERT_TRUE(fresh.join("", wire::kProtocolVersion, 40.0f));
  Received plain = loadCell(fresh, fx, kEye);
  ASSERT_TRUE(plain.ready);
  std::sort(plain.faces.begin(), plain.faces.end());
  ASSERT_FALSE(plain.faces.empty());
  for (const auto& [name, count] :
       {std::pair<std::string, uint32_t>{"another scene", fx.world().faceCount()},
        {fx.world().scene().name, fx.world().faceCount() + 1}}) {
    TestClient c(fx.port());
    helloHolding(c, name, count, held, 40.0f);
    ASSERT_TRUE(c.nextOf(Payload::Welcome));
    Received l = loadCell(c, fx, kEye);
    EXPECT_TRUE(l.ready);
    std::sort(l.faces.begin(), l.faces.end());
    EXPECT_EQ(l.faces, plain.faces) << name << " " << count;
  }
}

TEST(Failover, HeldFacesBeyondTheSceneGetBadRequestAndEndOnlyThatSession) {
  ServerFixture fx;
  TestClient bad(fx.port());
  helloHolding(bad, fx.world().scene().name, fx.world().faceCount(), {0, fx.world().faceCount()},
               40.0f);
  EXPECT_EQ(nextErrorCode(bad), wire::ErrorCode::BadRequest);
  TestClient good(fx.port());
  EXPECT_TRUE(good.join());
}

// ---- shared presence through Redis ----------------------------------------------

uint16_t freePort() {
  boost::asio::io_context io;
  boost::asio::ip::tcp::acceptor a(io, {boost::asio::ip::make_address("127.0.0.1"), 0});
  return a.local_endpoint().port();
}

bool accepts(uint16_t port) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::socket s(io);
  boost::system::error_code ec;
  s.connect({boost::asio::ip::make_address("127.0.0.1"), port}, ec);
  return !ec;
}

// redis-server on a loopback port for the test's lifetime (stop() and
// start() again on the same port to play an outage).
class RedisServer {
 public:
  RedisServer() : port_(freePort()) { start(); }
  ~RedisServer() { stop(); }
  void start() {
    const std::string port = std::to_string(port_);
    pid_ = fork();
    if (pid_ == 0) {
      // Not our test output's pipes: a child left behind must not hold them open.
      const int null = open("/dev/null", O_RDWR);
      dup2(null, 1);
      dup2(null, 2);
      execlp("redis-server", "redis-server", "--port", port.c_str(), "--bind", "127.0.0.1",
             "--save", "", "--appendonly", "no", "--loglevel", "warning",
             static_cast<char*>(nullptr));
      _exit(127);
    }
    for (int i = 0; i < 100 && !accepts(port_); ++i) usleep(50'000);
    ASSERT_TRUE(accepts(port_))
        << "redis-server did not start (deploy/install-deps.sh installs it)";
  }
  void stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }
  RedisAddress address() const { return {"127.0.0.1", port_}; }

 private:
  uint16_t port_;
  pid_t pid_ = -1;
};

StreamServerConfig replicaConfig(const RedisServer& redis) {
  return configWith([&](StreamServerConfig& c) {
    c.avatarHz = 20.0;
    c.presence = redis.address();
    c.presenceStaleS = 1.0;
  });
}

// Waits for an Avatar update naming `id` (true), or one departing it.
bool seesAvatar(TestClient& c, uint32_t id, double timeoutS) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeoutS);
  while (std::chrono::steady_clock::now() < end) {
    auto f = c.nextOf(Payload::Avatar, 0.2);
    if (!f) continue;
    if (const auto* avatars = wire::envelopeOf(*f)->payload_as_Avatar()->avatars())
      for (const auto* s : *avatars)
        if (s->session_id() == id) return true;
  }
  return false;
}
bool seesDeparture(TestClient& c, uint32_t id, double timeoutS) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeoutS);
  while (std::chrono::steady_clock::now() < end) {
    auto f = c.nextOf(Payload::Avatar, 0.2);
    if (!f) continue;
    if (const auto* d = wire::envelopeOf(*f)->payload_as_Avatar()->departed())
      for (uint32_t x : *d)
        if (x == id) return true;
  }
  return false;
}

uint32_t joinedSession(TestClient& c) {
  c.hello();
  const auto w = c.nextOf(Payload::Welcome);
  EXPECT_TRUE(w);
  return w ? wire::envelopeOf(*w)->payload_as_Welcome()->session_id() : 0;
}

bool waitFor(const std::function<bool()>& condition, double timeoutS) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeoutS);
  while (std::chrono::steady_clock::now() < end) {
    if (condition()) return true;
    usleep(20'000);
  }
  return condition();
}

TEST(Presence, UsersOnOneReplicaAppearOnTheOtherAndDepartFromIt) {
  RedisServer redis;
  ServerFixture one(replicaConfig(redis)), two(replicaConfig(redis));
  ASSERT_NE(one.server().replicaTag(), two.server().replicaTag());
  TestClient a(one.port()), b(two.port()), hidden(two.port());
  const uint32_t idA = joinedSession(a), idB = joinedSession(b), idHidden = joinedSession(hidden);
  // Session IDs carry their replica's tag.
  EXPECT_EQ(idA >> 24, one.server().replicaTag());
  EXPECT_EQ(idB >> 24, two.server().replicaTag());
  a.pose({-10.0, 1.7, 8.0});
  b.pose({10.0, 1.7, 8.0});        // in view of a, on the other replica
  hidden.pose({0.0, 1.7, -25.0});  // behind the wall: filtered by a's replica
  EXPECT_TRUE(seesAvatar(a, idB, 5.0)) << "a user of the other replica never appeared";
  EXPECT_TRUE(seesAvatar(b, idA, 5.0));
  EXPECT_FALSE(seesAvatar(a, idHidden, 1.0)) << "a hidden user of the other replica was sent";
  b.sendRaw(wire::encodeBye("leaving"));
  EXPECT_TRUE(seesDeparture(a, idB, 5.0)) << "a user who left the other replica never departed";
  const RedisPresence::Counters c = one.server().presence()->counters();
  EXPECT_TRUE(c.connected);
  EXPECT_GT(c.received, 0u);
  EXPECT_EQ(c.malformed, 0u);
  EXPECT_TRUE(one.server().presence()->latencyQuantile(0.5).has_value());
}

TEST(Presence, AReplicaThatLosesRedisServesItsOwnUsersAndRejoins) {
  RedisServer redis;
  ServerFixture one(replicaConfig(redis)), two(replicaConfig(redis));
  TestClient a(one.port()), b(two.port());
  joinedSession(a);
  const uint32_t idB = joinedSession(b);
  a.pose({-10.0, 1.7, 8.0});
  b.pose({10.0, 1.7, 8.0});
  ASSERT_TRUE(seesAvatar(a, idB, 5.0));

  redis.stop();
  const RedisPresence& presence = *one.server().presence();
  EXPECT_TRUE(waitFor([&] { return !presence.counters().connected; }, 5.0));
  // The other replica's user goes stale and departs; local users are served.
  EXPECT_TRUE(seesDeparture(a, idB, 5.0));
  TestClient local(one.port());
  ASSERT_TRUE(local.join());
  local.pose({0.0, 1.7, 8.0});
  EXPECT_TRUE(local.nextOf(Payload::Geometry)) << "a replica without Redis stopped serving";
  EXPECT_GE(presence.counters().lost, 1u);

  redis.start();
  EXPECT_TRUE(waitFor([&] { return presence.counters().connected; }, 10.0))
      << "the replica did not rejoin Redis";
  b.pose({10.0, 1.7, 8.5});
  EXPECT_TRUE(seesAvatar(a, idB, 5.0)) << "users of the other replica did not come back";
}

TEST(Presence, MessagesReadBackAndMalformedOnesAreRefusedNamingWhatIsWrong) {
  const std::vector<PresenceUser> users{{7, {1.5, 2.0, -3.25}, 90.0f, -5.0f, 1.4f, 1, 0.75f},
                                        {(3u << 24) | 9, {0, 0, 0}, 0, 0, 0, 0, 0}};
  std::string error;
  const auto m = parsePresence(encodePresence(3, 123456, users), error);
  ASSERT_TRUE(m) << error;
  EXPECT_EQ(m->replica, 3);
  EXPECT_EQ(m->sentMicros, 123456);
  ASSERT_EQ(m->users.size(), 2u);
  EXPECT_EQ(m->users[0].id, 7u);
  EXPECT_EQ(m->users[0].position, glm::dvec3(1.5, 2.0, -3.25));
  EXPECT_EQ(m->users[0].gait, 1);
  EXPECT_EQ(m->users[0].phaseS, 0.75f);
  EXPECT_EQ(m->users[1].id, (3u << 24) | 9);
  const std::pair<const char*, const char*> bad[] = {
      {"not json", "JSON"},
      {"[1,2]", "JSON object"},
      {R"({"v":2,"replica":1,"sent_us":0,"users":[]})", "\"v\""},
      {R"({"v":1,"replica":0,"sent_us":0,"users":[]})", "replica"},
      {R"({"v":1,"replica":256,"sent_us":0,"users":[]})", "replica"},
      {R"({"v":1,"replica":1,"sent_us":"x","users":[]})", "sent_us"},
      {R"({"v":1,"replica":1,"sent_us":0,"users":{}})", "users"},
      {R"({"v":1,"replica":1,"sent_us":0,"users":[[1,2,3]]})", "user 0"},
      {R"({"v":1,"replica":1,"sent_us":0,"users":[[1,0,0,0,0,0,0,3,0]]})", "user 0"},
      {R"({"v":1,"replica":1,"sent_us":0,"users":[[-1,0,0,0,0,0,0,0,0]]})", "user 0"},
      {R"({"v":1,"replica":1,"sent_us":0,"users":[[1,0,"y",0,0,0,0,0,0]]})", "field 2"},
  };
  for (const auto& [text, expected] : bad) {
    error.clear();
    EXPECT_FALSE(parsePresence(text, error)) << text;
    EXPECT_NE(error.find(expected), std::string::npos) << text << " -> " << error;
  }
}

TEST(Presence, RedisUrlsAreReadOrRefusedNamingTheProblem) {
  EXPECT_EQ(parseRedisUrl("redis://cache").host, "cache");
  EXPECT_EQ(parseRedisUrl("redis://cache").port, 6379);
  EXPECT_EQ(parseRedisUrl("redis://127.0.0.1:7000/").port, 7000);
  for (const char* bad : {"cache:6379", "redis://", "redis://:7000", "redis://h:0",
                          "redis://h:70000", "redis://h:port", "redis://user@h:1"}) {
    try {
      parseRedisUrl(bad);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--presence"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace vistream
