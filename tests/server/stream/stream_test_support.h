// A loopback test harness for the streaming server: a server on a small
// hand-built scene running on its own thread, and blocking test clients
// with timeouts.
#pragma once

#include <gtest/gtest.h>

#include <boost/asio.hpp>
#include <chrono>
#include <memory>
#include <optional>
#include <set>
#include <thread>
#include <vector>

#include "protocol/geometry/geometry_codec.h"
#include "protocol/wire/messages.h"
#include "server/stream/stream_server.h"
#include "tests/common/support/box_scenes.h"

namespace vistream::testing {

// A 60 m square of ground with a wall across it and boxes on both sides.
inline Scene streetScene() {
  Scene s;
  addGround(s, -30, -30, 30, 30);
  addBox(s, "wall", {-30, 0, -0.2f}, {30, 6, 0.2f});
  for (int i = 0; i < 6; ++i) {
    const float x = -25.0f + 10.0f * float(i);
    addBox(s, "north_" + std::to_string(i), {x, 0, -20}, {x + 4, 3, -16});
    addBox(s, "south_" + std::to_string(i), {x, 0, 16}, {x + 4, 3, 20});
  }
  finalizeScene(s);
  s.name = "street";
  return s;
}

// The default server configuration with `change` applied, for a fixture
// that differs in a setting or two:
// ServerFixture fx(configWith([](StreamServerConfig& c) { c.maxClients = 1; }));
template <class Change>
StreamServerConfig configWith(Change change) {
  StreamServerConfig config;
  change(config);
  return config;
}

class ServerFixture {
 public:
  explicit ServerFixture(StreamServerConfig config = {}, Scene scene = streetScene(),
                         StreamWorldOptions wo = {}) {
    world_ = std::make_unique<StreamWorld>(std::move(scene), wo);
    config.port = 0;
    config.workerThreads = 2;
    server_ = std::make_unique<StreamServer>(*world_, config);
    server_->start();
    thread_ = std::thread([this] { server_->run(false); });
  }
  ~ServerFixture() { shutDown(); }
  // Stops the server and waits for its threads and worker pool; the world
  // (and its statistics) stays.
  void shutDown() {
    if (!server_) return;
    server_->stop();
    thread_.join();
    server_.reset();
  }
  uint16_t port() const { return server_->port(); }
  StreamWorld& world() { return *world_; }
  StreamServer& server() { return *server_; }

 private:
  std::unique_ptr<StreamWorld> world_;
  std::unique_ptr<StreamServer> server_;
  std::thread thread_;
};

class TestClient {
 public:
  explicit TestClient(uint16_t port, int receiveBuffer = 0) : socket_(io_), decoder_(64u << 20) {
    socket_.open(boost::asio::ip::tcp::v4());
    if (receiveBuffer > 0)
      socket_.set_option(boost::asio::socket_base::receive_buffer_size(receiveBuffer));
    socket_.connect({boost::asio::ip::make_address("127.0.0.1"), port});
  }
  // Writes the bytes: true if they were written, false if the server had
  // already closed the connection (a test that floods a server which then
  // refuses it sees a broken pipe, not an exception).
  bool sendRaw(const std::vector<uint8_t>& bytes) {
    boost::system::error_code ec;
    boost::asio::write(socket_, boost::asio::buffer(bytes), ec);
    return !ec;
  }
  void hello(const std::string& token = "", uint32_t version = wire::kProtocolVersion,
             float radius = 0.0f, uint64_t budget = 0, bool avatars = true) {
    wire::HelloT h;
    h.protocol_version = version;
    h.auth_token = token;
    h.capabilities = std::make_unique<wire::CapabilitiesT>();
    h.capabilities->near_field_radius_m = radius;
    h.capabilities->memory_budget_bytes = budget;
    h.capabilities->wants_avatars = avatars;
    sendRaw(wire::encodeMessage(std::move(h)));
  }
  // Sends a Hello (arguments as for hello) and waits for the Welcome: true if
  // it came within 5 s.
  bool join(const std::string& token = "", uint32_t version = wire::kProtocolVersion,
            float radius = 0.0f, uint64_t budget = 0) {
    hello(token, version, radius, budget);
    return nextOf(wire::Payload::Welcome).has_value();
  }
  // Sends a Pose: true if it was written (see sendRaw).
  bool pose(const glm::dvec3& p, float yaw = 0.0f, glm::vec3 velocity = glm::vec3(0.0f)) {
    wire::PoseT m;
    m.position = std::make_unique<wire::Vec3d>(wire::toWire(p));
    m.yaw_deg = yaw;
    m.velocity = std::make_unique<wire::Vec3f>(wire::toWire(velocity));
    return sendRaw(wire::encodeMessage(std::move(m)));
  }
  // The next frame within the timeout, or nothing (timeout or closed).
  std::optional<std::vector<uint8_t>> next(double timeoutS = 5.0) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                              std::chrono::duration<double>(timeoutS));
    while (true) {
      if (auto f = decoder_.next()) return f;
      if (closed_ || decoder_.failed()) return std::nullopt;
      const auto now = std::chrono::steady_clock::now();
      if (now >= deadline) return std::nullopt;
      bool done = false;
      size_t got = 0;
      boost::system::error_code err;
      socket_.async_read_some(boost::asio::buffer(buffer_),
                              [&](const boost::system::error_code& ec, size_t n) {
                                done = true;
                                err = ec;
                                got = n;
                              });
      io_.restart();
      io_.run_for(deadline - now);
      if (!done) {
        socket_.cancel();
        io_.restart();
        io_.run();
        if (got == 0) return decoder_.next();
      }
      if (err && got == 0) {
        closed_ = true;
        continue;
      }
      bytes_ += got;
      decoder_.feed(std::span<const uint8_t>(buffer_.data(), got));
    }
  }
  // The next frame of the given payload type (skipping others), or nothing.
  std::optional<std::vector<uint8_t>> nextOf(wire::Payload type, double timeoutS = 5.0) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(timeoutS));
    while (std::chrono::steady_clock::now() < end) {
      const double left =
          std::chrono::duration<double>(end - std::chrono::steady_clock::now()).count();
      auto f = next(std::max(0.01, left));
      if (!f) return std::nullopt;
      if (wire::envelopeOf(*f)->payload_type() == type) return f;
      onOther(*f);
    }
    return std::nullopt;
  }
  // Reads until the server closes the connection; true if it did in time.
  bool closedWithin(double timeoutS) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(timeoutS));
    while (!closed_ && std::chrono::steady_clock::now() < end) {
      auto f = next(0.2);
      if (f) onOther(*f);
    }
    return closed_;
  }
  // Frames skipped by nextOf/closedWithin are recorded here.
  std::vector<std::vector<uint8_t>> skipped;
  uint64_t bytes() const { return bytes_; }
  boost::asio::ip::tcp::socket& socket() { return socket_; }

 private:
  void onOther(const std::vector<uint8_t>& f) { skipped.push_back(f); }
  boost::asio::io_context io_;
  boost::asio::ip::tcp::socket socket_;
  wire::FrameDecoder decoder_;
  std::array<uint8_t, 65536> buffer_{};
  bool closed_ = false;
  uint64_t bytes_ = 0;
};

// Faces decoded from every Geometry frame until CellReady for `cell` (or the timeout).
struct Received {
  std::vector<uint32_t> faces;  // in arrival order, duplicates kept
  std::vector<wire::DecodedGeometry> batches;
  bool ready = false;
  size_t evictions = 0;
  std::set<uint32_t> held() const { return {faces.begin(), faces.end()}; }
};

// `grid`: the scene's quantization grid, as the server's Welcome sends it.
inline Received receiveUntilReady(TestClient& c, const glm::ivec3& cell,
                                  const wire::QuantizationGrid& grid, double timeoutS = 10.0) {
  Received r;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(int(timeoutS));
  while (!r.ready && std::chrono::steady_clock::now() < end) {
    auto f = c.next(0.5);
    if (!f) continue;
    const auto* e = wire::envelopeOf(*f);
    if (e->payload_type() == wire::Payload::Geometry) {
      wire::DecodedGeometry g;
      std::string error;
      EXPECT_TRUE(wire::decodeGeometry(*e->payload_as_Geometry(), grid, g, error)) << error;
      r.faces.insert(r.faces.end(), g.faces.begin(), g.faces.end());
      r.batches.push_back(std::move(g));
    } else if (e->payload_type() == wire::Payload::CellReady) {
      for (const glm::ivec3& announced : wire::readyCells(*e->payload_as_CellReady()))
        r.ready = r.ready || announced == cell;
    } else if (e->payload_type() == wire::Payload::Evict) {
      ++r.evictions;
    }
  }
  return r;
}

// The code of the next Error frame within the timeout, or nothing.
inline std::optional<wire::ErrorCode> nextErrorCode(TestClient& c, double timeoutS = 5.0) {
  const auto f = c.nextOf(wire::Payload::Error, timeoutS);
  if (!f) return std::nullopt;
  return wire::envelopeOf(*f)->payload_as_Error()->code();
}

// Expects the next Error frame to carry `code` and the server to close the
// connection after it, within 3 s.
inline void expectRefusedAndClosed(TestClient& c, wire::ErrorCode code) {
  EXPECT_EQ(nextErrorCode(c), code);
  EXPECT_TRUE(c.closedWithin(3.0));
}

// An honest client: Hello, then a pose; true once it holds its cell's whole
// face set (CellReady) within the timeout.
inline bool honestClientLoads(uint16_t port, const glm::dvec3& position, double timeoutS) {
  TestClient c(port);
  c.hello();
  if (!c.nextOf(wire::Payload::Welcome, timeoutS)) return false;
  c.pose(position);
  return c.nextOf(wire::Payload::CellReady, timeoutS).has_value();
}

}  // namespace vistream::testing
