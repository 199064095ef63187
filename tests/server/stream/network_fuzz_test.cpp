// A network mutation fuzzer against a live server: real client sessions
// (Hello, a walk of Poses, PvsRequests, Bye), mutated at the byte and at the
// field level, replayed over loopback by several connections at once, in
// random chunks and with random pauses, while an honest client keeps
// checking that it is still served. The server runs in this process, so a
// crash fails the test and a hang trips ctest's timeout.
//
// Bounded in time: VISTREAM_FUZZ_SECONDS (default 45). The seed is fixed so
// that CI runs are comparable; VISTREAM_FUZZ_SEED picks another (printed).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <limits>
#include <random>

#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

using Clock = std::chrono::steady_clock;
using Bytes = std::vector<uint8_t>;

double envSeconds(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v ? std::atof(v) : fallback;
}

// Values that have broken servers, for float and double fields alike:
// extremes, non-finite, signed zero, denormals, numbers whose float square
// overflows (1e19 and up) and integers at the edge of 16 and 32 bits.
template <class T>
T nasty(std::mt19937_64& rng) {
  using Limits = std::numeric_limits<T>;
  static const T values[] = {T(0),
                             -T(0),
                             Limits::max(),
                             Limits::lowest(),
                             Limits::denorm_min(),
                             Limits::infinity(),
                             -Limits::infinity(),
                             Limits::quiet_NaN(),
                             T(1e30),
                             T(-1e30),
                             T(1e19),
                             T(9.3e18),
                             T(1e7),
                             T(65535),
                             T(2147483648.0),
                             T(1e-7)};
  return values[rng() % std::size(values)];
}

// One real session as a client sends it, with optional field-level
// mutations (each message's fields replaced by nasty values at random).
Bytes realSession(std::mt19937_64& rng, bool mutateFields) {
  auto pick = [&](double p) {
    return mutateFields && std::uniform_real_distribution<double>(0, 1)(rng) < p;
  };
  Bytes out;
  auto append = [&](const Bytes& f) { out.insert(out.end(), f.begin(), f.end()); };
  wire::HelloT h;
  h.protocol_version = pick(0.05) ? uint32_t(rng()) : wire::kProtocolVersion;
  h.capabilities = std::make_unique<wire::CapabilitiesT>();
  h.capabilities->near_field_radius_m = pick(0.2) ? nasty<float>(rng) : 60.0f;
  h.capabilities->memory_budget_bytes = pick(0.2) ? rng() % 4096 : 0;
  h.capabilities->wants_avatars = true;
  h.client_name = "fuzz";
  append(wire::encodeMessage(std::move(h)));
  const int poses = 5 + int(rng() % 40);
  for (int i = 0; i < poses; ++i) {
    const double t = 0.1 * i;
    if (rng() % 8 == 0) {
      wire::PvsRequestT q;
      q.request_id = uint32_t(rng());
      q.by_cell = rng() % 2;
      if (q.by_cell)
        q.cell = std::make_unique<wire::CellIndex>(pick(0.3) ? int(rng()) : int(rng() % 16),
                                                   int(rng() % 2),
                                                   pick(0.3) ? -int(rng() % 100) : int(rng() % 16));
      else
        q.point = std::make_unique<wire::Vec3d>(
            pick(0.3) ? nasty<double>(rng) : -25.0 + 50.0 * double(rng() % 100) / 100, 1.7,
            pick(0.3) ? nasty<double>(rng) : 8.0);
      append(wire::encodeMessage(std::move(q)));
      continue;
    }
    wire::PoseT p;
    glm::dvec3 pos(-25.0 + 1.4 * t, 1.7, 8.0);
    if (pick(0.1)) pos.x = nasty<double>(rng);
    if (pick(0.1)) pos.z = nasty<double>(rng);
    if (pick(0.05)) pos = glm::dvec3(rng() % 1000, 0.0, rng() % 1000);  // teleport
    p.position = std::make_unique<wire::Vec3d>(wire::toWire(pos));
    p.yaw_deg = pick(0.1) ? nasty<float>(rng) : float(i * 7 % 360);
    p.pitch_deg = pick(0.1) ? nasty<float>(rng) : 0.0f;
    glm::vec3 v(1.4f, 0.0f, 0.0f);
    if (pick(0.15)) v = glm::vec3(nasty<float>(rng), nasty<float>(rng), nasty<float>(rng));
    p.velocity = std::make_unique<wire::Vec3f>(wire::toWire(v));
    p.client_time_s = pick(0.1) ? nasty<double>(rng) : t;
    append(wire::encodeMessage(std::move(p)));
  }
  if (rng() % 2) append(wire::encodeBye("done"));
  return out;
}

// Byte-level mutations of a whole session's bytes.
void mutateBytes(Bytes& b, std::mt19937_64& rng) {
  const int edits = 1 + int(rng() % 8);
  for (int e = 0; e < edits && !b.empty(); ++e) {
    const size_t at = rng() % b.size();
    switch (rng() % 7) {
      case 0:
        b[at] ^= uint8_t(1u << (rng() % 8));
        break;  // bit flip
      case 1:
        b[at] = uint8_t(rng());
        break;  // byte
      case 2:
        b.insert(b.begin() + std::ptrdiff_t(at), uint8_t(rng()));
        break;
      case 3:
        b.erase(b.begin() + std::ptrdiff_t(at));
        break;
      case 4:
        b.resize(at);
        break;   // truncation
      case 5: {  // a run duplicated
        const size_t n = std::min<size_t>(b.size() - at, 1 + rng() % 64);
        Bytes run(b.begin() + std::ptrdiff_t(at), b.begin() + std::ptrdiff_t(at + n));
        b.insert(b.begin() + std::ptrdiff_t(at), run.begin(), run.end());
        break;
      }
      default: {  // an interesting 32-bit value
        static const uint32_t values[] = {0u,          1u,     0x7fffffffu, 0x80000000u,
                                          0xffffffffu, 65536u, 65537u};
        const uint32_t v = values[rng() % std::size(values)];
        for (int k = 0; k < 4 && at + size_t(k) < b.size(); ++k)
          b[at + size_t(k)] = uint8_t(v >> (8 * k));
      }
    }
  }
}

// Sends the bytes in random chunks with random pauses, reads (or not)
// whatever comes back, and hangs up, politely or not.
void replay(uint16_t port, const Bytes& bytes, std::mt19937_64& rng) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::socket s(io);
  boost::system::error_code ec;
  s.connect({boost::asio::ip::make_address("127.0.0.1"), port}, ec);
  if (ec) return;
  size_t at = 0;
  while (at < bytes.size()) {
    const size_t n = std::min(bytes.size() - at, size_t(1 + rng() % 512));
    boost::asio::write(s, boost::asio::buffer(bytes.data() + at, n), ec);
    if (ec) return;
    at += n;
    if (rng() % 16 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(rng() % 30));
  }
  if (rng() % 3) {  // read what the server says for a moment
    s.non_blocking(true, ec);
    std::array<uint8_t, 65536> buf{};
    const auto end = Clock::now() + std::chrono::milliseconds(rng() % 200);
    while (Clock::now() < end) {
      s.read_some(boost::asio::buffer(buf), ec);
      if (ec == boost::asio::error::would_block)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      else if (ec)
        break;
    }
  }
  if (rng() % 2) s.set_option(boost::asio::socket_base::linger(true, 0), ec);  // reset, not FIN
  s.close(ec);
}

TEST(NetworkFuzz, MutatedRealSessionsNeverStopTheServerFromServingHonestClients) {
  const double seconds = envSeconds("VISTREAM_FUZZ_SECONDS", 45.0);
  const uint64_t seed = std::getenv("VISTREAM_FUZZ_SEED")
                            ? std::strtoull(std::getenv("VISTREAM_FUZZ_SEED"), nullptr, 10)
                            : uint64_t(20261201);
  std::printf("network fuzz: seed %llu, %.0f s\n", static_cast<unsigned long long>(seed), seconds);
  ServerFixture server(configWith([](StreamServerConfig& c) {
    c.helloTimeoutS = 2.0;
    c.frameTimeoutS = 2.0;
  }));
  const uint16_t port = server.port();
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(seconds));

  std::atomic<uint64_t> sessions{0};
  std::vector<std::thread> attackers;
  for (int t = 0; t < 4; ++t)
    attackers.emplace_back([&, t] {
      std::mt19937_64 rng(seed + uint64_t(t) * 7919u);
      while (Clock::now() < end) {
        Bytes b = realSession(rng, rng() % 2);
        if (rng() % 4 != 0) mutateBytes(b, rng);
        if (rng() % 10 == 0) {  // spliced with another session
          Bytes other = realSession(rng, false);
          b.resize(rng() % (b.size() + 1));
          b.insert(b.end(), other.begin() + std::ptrdiff_t(rng() % other.size()), other.end());
        }
        replay(port, b, rng);
        ++sessions;
      }
    });

  // The honest client: every second, a fresh connection must be welcomed
  // and receive its cell's whole face set.
  int honest = 0, served = 0;
  while (Clock::now() < end) {
    ++honest;
    served += honestClientLoads(port, {-10.0 + double(honest % 20), 1.7, 8.0}, 10.0);
    std::this_thread::sleep_for(std::chrono::seconds(1));
  }
  for (auto& t : attackers) t.join();
  std::printf("network fuzz: %llu mutated sessions, honest client served %d of %d times\n",
              static_cast<unsigned long long>(sessions.load()), served, honest);
  EXPECT_GT(sessions.load(), 100u);
  EXPECT_EQ(served, honest) << "seed " << seed;
  // And the server still stops cleanly (the fixture's destructor joins it).
}

}  // namespace
}  // namespace vistream::testing
