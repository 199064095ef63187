// Capabilities.stats_interval_s (protocol version 3): a client may ask for
// fewer Stats frames, never more than the server's interval, and a value
// that is negative or not finite is refused at Hello.
#include <gtest/gtest.h>

#include <chrono>
#include <limits>

#include "tests/server/stream/stream_test_support.h"

namespace vistream::testing {
namespace {

void helloWithStatsInterval(TestClient& c, float seconds) {
  wire::HelloT h;
  h.protocol_version = wire::kProtocolVersion;
  h.capabilities = std::make_unique<wire::CapabilitiesT>();
  h.capabilities->stats_interval_s = seconds;
  c.sendRaw(wire::encodeMessage(std::move(h)));
}

// Stats frames a client receives in `seconds` of wall time after its Welcome.
size_t statsWithin(TestClient& c, double seconds) {
  size_t n = 0;
  const auto end = std::chrono::steady_clock::now() +
                   std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                       std::chrono::duration<double>(seconds));
  while (std::chrono::steady_clock::now() < end)
    if (auto f = c.next(0.05); f && wire::envelopeOf(*f)->payload_type() == wire::Payload::Stats)
      ++n;
  return n;
}

TEST(SessionStatsInterval, AClientAskingForFewerStatsGetsFewerAndNoneAsksForMore) {
  ServerFixture fx(configWith([](StreamServerConfig& c) { c.clientStatsIntervalS = 0.3; }));
  TestClient fewer(fx.port()), eager(fx.port()), plain(fx.port());
  helloWithStatsInterval(fewer, 100.0f);
  helloWithStatsInterval(eager, 0.01f);  // more often than the server's: the server's interval
  helloWithStatsInterval(plain, 0.0f);   // the server's interval
  for (TestClient* c : {&fewer, &eager, &plain})
    ASSERT_TRUE(c->nextOf(wire::Payload::Welcome).has_value());
  // 1.5 s at 0.3 s: about 5 frames each (the first right after the Welcome).
  const size_t nFewer = statsWithin(fewer, 1.5), nEager = statsWithin(eager, 1.5),
               nPlain = statsWithin(plain, 1.5);
  EXPECT_LE(nFewer, 1u) << "asked for one every 100 s";
  EXPECT_GE(nPlain, 3u);
  EXPECT_LE(nEager, nPlain + 1) << "never more often than the server's interval";
}

TEST(SessionStatsInterval, ANegativeOrNonFiniteIntervalIsRefusedNamingTheField) {
  ServerFixture fx;
  for (float bad :
       {-1.0f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    SCOPED_TRACE(bad);
    TestClient c(fx.port());
    helloWithStatsInterval(c, bad);
    const auto f = c.nextOf(wire::Payload::Error, 5.0);
    ASSERT_TRUE(f.has_value());
    const wire::Error* e = wire::envelopeOf(*f)->payload_as_Error();
    EXPECT_EQ(e->code(), wire::ErrorCode::BadRequest);
    ASSERT_NE(e->text(), nullptr);
    EXPECT_NE(e->text()->str().find("stats_interval_s"), std::string::npos) << e->text()->str();
    EXPECT_TRUE(c.closedWithin(3.0));
  }
}

}  // namespace
}  // namespace vistream::testing
