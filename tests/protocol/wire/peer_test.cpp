// The protocol peer core (protocol/wire/peer.h): Welcome checks, typed
// dispatch, the outbox's rules, and a Peer over real loopback sockets against
// a plain blocking socket that writes and reads raw frames.
#include "protocol/wire/peer.h"

#include <gtest/gtest.h>

#include <array>
#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <functional>
#include <future>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>  // before Boost.Asio
#include <vector>

namespace vistream::wire {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;

WelcomeT goodWelcome() {
  WelcomeT w;
  w.protocol_version = kProtocolVersion;
  w.local_origin = std::make_unique<Vec3d>(1000.0, 0.0, -2000.0);
  w.grid = std::make_unique<CellGridT>();
  w.grid->origin = std::make_unique<Vec3f>(-8.0f, 0.0f, -8.0f);
  w.grid->cell_size = std::make_unique<Vec3f>(4.0f, 3.0f, 4.0f);
  w.grid->dims = std::make_unique<CellIndex>(4, 1, 4);
  w.near_field_radius_m = 100.0f;
  w.face_count = 12;
  w.quant_origin = std::make_unique<Vec3d>(-8.0, 0.0, -8.0);
  w.quant_step = 1e-3;
  return w;
}

// The Welcome as a receiver sees it: encoded, decoded and verified.
struct ReceivedWelcome {
  std::vector<uint8_t> frame;
  const Welcome& get() const { return *envelopeOf(frame)->payload_as_Welcome(); }
};
ReceivedWelcome receive(WelcomeT w) {
  FrameDecoder decoder;
  EXPECT_TRUE(decoder.feed(encodeMessage(std::move(w))));
  auto frame = decoder.next();
  EXPECT_TRUE(frame.has_value());
  return {frame.value_or(std::vector<uint8_t>{})};
}

// The InputError validateWelcome throws, or nothing.
std::optional<InputError> refusalOf(WelcomeT w, uint32_t maxFaces = kMaxWelcomeFaceCount) {
  const ReceivedWelcome r = receive(std::move(w));
  try {
    validateWelcome(r.get(), maxFaces);
  } catch (const InputError& e) {
    return e;
  }
  return std::nullopt;
}

void expectRefusedNaming(const std::optional<InputError>& e, const std::string& field) {
  ASSERT_TRUE(e.has_value()) << "accepted; expected a refusal naming " << field;
  EXPECT_EQ(e->code(), InputErrorCode::BadFrame);
  EXPECT_NE(std::string(e->what()).find(field), std::string::npos) << e->what();
}

TEST(ValidateWelcome, ReturnsTheGridTheServerSent) {
  const ReceivedWelcome r = receive(goodWelcome());
  const WelcomeGrid g = validateWelcome(r.get());
  EXPECT_EQ(g.localOrigin, glm::dvec3(1000.0, 0.0, -2000.0));
  EXPECT_EQ(g.gridOrigin, glm::vec3(-8.0f, 0.0f, -8.0f));
  EXPECT_EQ(g.cellSize, glm::vec3(4.0f, 3.0f, 4.0f));
  EXPECT_EQ(g.dims, glm::ivec3(4, 1, 4));
  EXPECT_EQ(g.radius, 100.0f);
  EXPECT_EQ(g.faceCount, 12u);
  EXPECT_EQ(g.quantization.origin, glm::dvec3(-8.0, 0.0, -8.0));
  EXPECT_EQ(g.quantization.step, 1e-3);
}

TEST(ValidateWelcome, PlacesPointsInTheirCellsAndClampsThoseOutside) {
  const ReceivedWelcome r = receive(goodWelcome());
  const WelcomeGrid g = validateWelcome(r.get());
  // x: (-3 + 8) / 4 = 1.25, y: 1.7 / 3, z: (7.9 + 8) / 4 = 3.975.
  EXPECT_EQ(g.cellOf({-3.0f, 1.7f, 7.9f}), glm::ivec3(1, 0, 3));
  EXPECT_EQ(g.cellOf({-100.0f, -5.0f, 100.0f}), glm::ivec3(0, 0, 3));
}

TEST(ValidateWelcome, RefusesAZeroCellSizeNamingTheField) {
  WelcomeT w = goodWelcome();
  w.grid->cell_size = std::make_unique<Vec3f>(4.0f, 0.0f, 4.0f);
  expectRefusedNaming(refusalOf(std::move(w)), "Welcome.grid.cell_size");
}

TEST(ValidateWelcome, RefusesANegativeOrNonFiniteCellSize) {
  WelcomeT negative = goodWelcome();
  negative.grid->cell_size = std::make_unique<Vec3f>(-4.0f, 3.0f, 4.0f);
  expectRefusedNaming(refusalOf(std::move(negative)), "Welcome.grid.cell_size");
  WelcomeT nan = goodWelcome();
  nan.grid->cell_size = std::make_unique<Vec3f>(4.0f, 3.0f, std::nanf(""));
  expectRefusedNaming(refusalOf(std::move(nan)), "Welcome.grid.cell_size");
}

TEST(ValidateWelcome, RefusesAMissingGrid) {
  WelcomeT w = goodWelcome();
  w.grid.reset();
  expectRefusedNaming(refusalOf(std::move(w)), "Welcome.grid");
}

TEST(ValidateWelcome, RefusesAMissingOrNonFiniteLocalOrigin) {
  WelcomeT missing = goodWelcome();
  missing.local_origin.reset();
  expectRefusedNaming(refusalOf(std::move(missing)), "Welcome.local_origin");
  WelcomeT infinite = goodWelcome();
  infinite.local_origin = std::make_unique<Vec3d>(0.0, HUGE_VAL, 0.0);
  expectRefusedNaming(refusalOf(std::move(infinite)), "Welcome.local_origin");
}

TEST(ValidateWelcome, RefusesAMissingNonFiniteOrNonPositiveQuantizationGrid) {
  WelcomeT missing = goodWelcome();
  missing.quant_origin.reset();
  expectRefusedNaming(refusalOf(std::move(missing)), "Welcome.quant_origin");
  WelcomeT infinite = goodWelcome();
  infinite.quant_origin = std::make_unique<Vec3d>(0.0, HUGE_VAL, 0.0);
  expectRefusedNaming(refusalOf(std::move(infinite)), "Welcome.quant_origin");
  for (double step : {0.0, -1e-3, std::nan(""), HUGE_VAL, 1e4}) {
    WelcomeT w = goodWelcome();
    w.quant_step = step;
    SCOPED_TRACE(step);
    expectRefusedNaming(refusalOf(std::move(w)), "Welcome.quant_step");
  }
}

TEST(ValidateWelcome, RefusesANegativeRadiusAndNegativeDims) {
  WelcomeT radius = goodWelcome();
  radius.near_field_radius_m = -1.0f;
  expectRefusedNaming(refusalOf(std::move(radius)), "Welcome.near_field_radius_m");
  WelcomeT dims = goodWelcome();
  dims.grid->dims = std::make_unique<CellIndex>(4, -1, 4);
  expectRefusedNaming(refusalOf(std::move(dims)), "Welcome.grid.dims");
}

TEST(ValidateWelcome, RefusesMoreFacesThanTheReceiverAllows) {
  expectRefusedNaming(refusalOf(goodWelcome(), 11), "Welcome.face_count");
  EXPECT_FALSE(refusalOf(goodWelcome(), 12).has_value());
}

TEST(DispatchPayload, CallsTheOverloadOfThePayloadsTypeAndTheFallbackForOthers) {
  std::vector<std::string> calls;
  const auto handler = Overloaded{
      [&](const Bye& bye) { calls.push_back("Bye:" + bye.reason()->str()); },
      [&](const Error& e) { calls.push_back("Error:" + std::to_string(int(e.code()))); },
      [&](Payload type) { calls.push_back(std::string("other:") + payloadName(type)); },
  };
  FrameDecoder decoder;
  for (const auto& frame : {encodeBye("done"), encodeError(ErrorCode::BadToken, "no"),
                            encodeHello(kProtocolVersion, "t")})
    ASSERT_TRUE(decoder.feed(frame));
  while (auto frame = decoder.next()) dispatchPayload(*envelopeOf(*frame), handler);
  EXPECT_EQ(calls, (std::vector<std::string>{"Bye:done", "Error:3", "other:Hello"}));
}

// ---- Outbox ----------------------------------------------------------------------

Outbox::Frame frameOf(size_t bytes, uint8_t fill) {
  return std::make_shared<const std::vector<uint8_t>>(bytes, fill);
}

TEST(Outbox, HasExactlyOneWriteInFlightAndSendsInOrder) {
  Outbox outbox(1000);
  ASSERT_TRUE(outbox.push(frameOf(10, 1)));
  ASSERT_TRUE(outbox.push(frameOf(20, 2)));
  const Outbox::Frame first = outbox.startWrite();
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(first->front(), 1);
  EXPECT_EQ(outbox.startWrite(), nullptr);  // the first is still in flight
  ASSERT_TRUE(outbox.push(frameOf(30, 3)));
  EXPECT_EQ(outbox.startWrite(), nullptr);
  outbox.finishWrite();
  EXPECT_EQ(outbox.queuedBytes(), 50u);
  const Outbox::Frame second = outbox.startWrite();
  ASSERT_NE(second, nullptr);
  EXPECT_EQ(second->front(), 2);
  outbox.finishWrite();
  EXPECT_EQ(outbox.startWrite()->front(), 3);
  outbox.finishWrite();
  EXPECT_TRUE(outbox.empty());
  EXPECT_EQ(outbox.queuedBytes(), 0u);
}

TEST(Outbox, CountsTheFrameInFlightAgainstItsLimit) {
  Outbox outbox(100);
  ASSERT_TRUE(outbox.push(frameOf(60, 1)));
  ASSERT_NE(outbox.startWrite(), nullptr);
  EXPECT_TRUE(outbox.push(frameOf(40, 2)));  // 100: at the limit
  EXPECT_FALSE(outbox.push(frameOf(1, 3)));  // 101: over it
}

TEST(Outbox, ClearedMidWriteForgetsEverythingAndAcceptsTheLateCompletion) {
  Outbox outbox(100);
  ASSERT_TRUE(outbox.push(frameOf(60, 1)));
  const Outbox::Frame inFlight = outbox.startWrite();
  outbox.clear();
  outbox.finishWrite();  // the write handler completes after the clear
  EXPECT_TRUE(outbox.empty());
  EXPECT_EQ(outbox.queuedBytes(), 0u);
  EXPECT_FALSE(outbox.writing());
  EXPECT_EQ(inFlight->size(), 60u);  // the handler's frame stayed valid
}

TEST(Outbox, ClearedMidWriteThenPushedSendsTheNewFrameAfterTheOneInFlight) {
  Outbox outbox(1000);
  ASSERT_TRUE(outbox.push(frameOf(60, 1)));
  ASSERT_TRUE(outbox.push(frameOf(20, 2)));  // queued, never written: cleared
  const Outbox::Frame inFlight = outbox.startWrite();
  ASSERT_NE(inFlight, nullptr);
  outbox.clear();
  EXPECT_EQ(outbox.queuedBytes(), 60u);  // the frame in flight still counts
  ASSERT_TRUE(outbox.push(frameOf(30, 3)));
  EXPECT_EQ(outbox.startWrite(), nullptr);  // still one write in flight
  outbox.finishWrite();                     // the write begun before the clear completes
  EXPECT_EQ(outbox.queuedBytes(), 30u);
  const Outbox::Frame next = outbox.startWrite();
  ASSERT_NE(next, nullptr);  // the new frame was not popped as if it had been sent
  EXPECT_EQ(next->size(), 30u);
  EXPECT_EQ(next->front(), 3);
  outbox.finishWrite();
  EXPECT_TRUE(outbox.empty());
  EXPECT_EQ(outbox.queuedBytes(), 0u);
}

TEST(Outbox, AbandonedWriteLeavesTheQueueWithoutItsFrame) {
  Outbox outbox(1000);
  ASSERT_TRUE(outbox.push(frameOf(60, 1)));
  ASSERT_TRUE(outbox.push(frameOf(20, 2)));
  ASSERT_NE(outbox.startWrite(), nullptr);
  outbox.abandonWrite();
  EXPECT_FALSE(outbox.writing());
  EXPECT_EQ(outbox.queuedBytes(), 20u);
  EXPECT_EQ(outbox.startWrite()->front(), 2);
}

// ---- Peer over loopback sockets --------------------------------------------------

// Records what a Peer reports; waits with a bound (a broken peer fails the
// test instead of hanging it).
class Recorder : public PeerHandler {
 public:
  std::function<void(const Envelope&)> also;  // runs on the peer's strand after recording

  void onFrame(const Envelope& e) override {
    {
      std::lock_guard lock(mutex_);
      types_.push_back(e.payload_type());
      if (e.payload_type() == Payload::Bye) reasons_.push_back(e.payload_as_Bye()->reason()->str());
    }
    changed_.notify_all();
    if (also) also(e);
  }
  void onPeerEnd(PeerEnd why, const std::string& text) override {
    {
      std::lock_guard lock(mutex_);
      ++ends_;
      end_ = why;
      endText_ = text;
    }
    changed_.notify_all();
  }
  bool waitForFrames(size_t n) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, std::chrono::seconds(10), [&] { return types_.size() >= n; });
  }
  bool waitForEnd() {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, std::chrono::seconds(10), [&] { return ends_ > 0; });
  }
  std::vector<std::string> reasons() const {
    std::lock_guard lock(mutex_);
    return reasons_;
  }
  size_t frames() const {
    std::lock_guard lock(mutex_);
    return types_.size();
  }
  int ends() const {
    std::lock_guard lock(mutex_);
    return ends_;
  }
  std::optional<PeerEnd> end() const {
    std::lock_guard lock(mutex_);
    return end_;
  }
  std::string endText() const {
    std::lock_guard lock(mutex_);
    return endText_;
  }

 private:
  mutable std::mutex mutex_;  // guards everything below
  std::condition_variable changed_;
  std::vector<Payload> types_;
  std::vector<std::string> reasons_;
  int ends_ = 0;
  std::optional<PeerEnd> end_;
  std::string endText_;
};

// A Peer connected over loopback to `raw`, a blocking socket the test drives.
class PeerPair {
 public:
  explicit PeerPair(const PeerOptions& options = {})
      : peer(Peer::create(asio::make_strand(io_), options)), raw(rawIo_) {
    tcp::acceptor acceptor(rawIo_, {asio::ip::make_address("127.0.0.1"), 0});
    peer->socket().connect(acceptor.local_endpoint());
    acceptor.accept(raw);
  }
  void start() {
    peer->start(recorder);
    thread_ = std::thread([this] { io_.run(); });
  }
  // Runs `f` on the peer's strand and waits for it.
  void onStrand(std::function<void()> f) {
    std::promise<void> done;
    asio::post(peer->strand(), [&] {
      f();
      done.set_value();
    });
    done.get_future().wait();
  }
  // Reads whole frames from the raw side until `n` arrived or the stream ends.
  std::vector<std::vector<uint8_t>> readFrames(size_t n) {
    std::vector<std::vector<uint8_t>> frames;
    FrameDecoder decoder(64u << 20);
    std::array<uint8_t, 4096> buf;
    boost::system::error_code ec;
    while (frames.size() < n && !ec) {
      const size_t got = raw.read_some(asio::buffer(buf), ec);
      if (!decoder.feed(std::span<const uint8_t>(buf.data(), got))) break;
      while (auto f = decoder.next()) frames.push_back(std::move(*f));
      if (decoder.failed()) break;
    }
    return frames;
  }
  ~PeerPair() {
    boost::system::error_code ignored;
    raw.close(ignored);
    asio::post(peer->strand(), [p = peer] { p->close(); });
    if (thread_.joinable()) thread_.join();
  }

 private:
  asio::io_context io_, rawIo_;

 public:
  std::shared_ptr<Peer> peer;
  tcp::socket raw;
  std::shared_ptr<Recorder> recorder = std::make_shared<Recorder>();

 private:
  std::thread thread_;
};

TEST(Peer, DeliversFramesInOrderHoweverTheBytesAreSplit) {
  PeerPair pair;
  pair.start();
  std::vector<uint8_t> bytes;
  std::vector<std::string> sent;
  for (int i = 0; i < 200; ++i) {
    sent.push_back("frame " + std::to_string(i) + std::string(size_t(i) * 37, 'x'));
    const auto f = encodeBye(sent.back());
    bytes.insert(bytes.end(), f.begin(), f.end());
  }
  // Chunks of 1, 2, 3, ... bytes: frame boundaries fall everywhere.
  for (size_t at = 0, chunk = 1; at < bytes.size(); at += chunk, ++chunk)
    asio::write(pair.raw, asio::buffer(bytes.data() + at, std::min(chunk, bytes.size() - at)));
  ASSERT_TRUE(pair.recorder->waitForFrames(sent.size()));
  EXPECT_EQ(pair.recorder->reasons(), sent);
  EXPECT_EQ(pair.peer->bytesReceived(), bytes.size());
  EXPECT_EQ(pair.recorder->ends(), 0);
}

TEST(Peer, SendsWholeFramesInOrderWhenManyThreadsSendAtOnce) {
  PeerPair pair;
  pair.start();
  constexpr int kThreads = 4, kFrames = 300;
  std::vector<std::thread> senders;
  for (int t = 0; t < kThreads; ++t)
    senders.emplace_back([&, t] {
      for (int i = 0; i < kFrames; ++i)
        pair.peer->send(encodeBye(std::to_string(t) + ":" + std::to_string(i) +
                                  std::string(size_t(i % 7) * 1000, '.')));
    });
  // Interleaved writes would tear frames apart: the decoder would fail.
  const auto frames = pair.readFrames(kThreads * kFrames);
  for (auto& s : senders) s.join();
  ASSERT_EQ(frames.size(), size_t(kThreads * kFrames));
  std::vector<int> next(kThreads, 0);
  for (const auto& f : frames) {
    const std::string reason = envelopeOf(f)->payload_as_Bye()->reason()->str();
    const int t = std::stoi(reason.substr(0, reason.find(':')));
    const int i = std::stoi(reason.substr(reason.find(':') + 1));
    EXPECT_EQ(i, next[size_t(t)]) << "sender " << t << " out of order";
    next[size_t(t)] = i + 1;
  }
}

TEST(Peer, AcceptsFramesUpToItsOutboxLimitAndEndsOnTheFirstBeyondIt) {
  const std::vector<uint8_t> frame = encodeBye(std::string(64 * 1024, 'b'));
  PeerPair pair({.outboxLimitBytes = 16 * frame.size()});
  pair.start();
  // From the strand, so no write can complete between the sends.
  bool openAfter16 = false;
  pair.onStrand([&] {
    for (int i = 0; i < 16; ++i) pair.peer->send(frame);
    openAfter16 = pair.peer->open();
    pair.peer->send(frame);
  });
  EXPECT_TRUE(openAfter16);
  ASSERT_TRUE(pair.recorder->waitForEnd());
  EXPECT_EQ(pair.recorder->end(), PeerEnd::OutboxFull);
  EXPECT_NE(pair.recorder->endText().find(std::to_string(17 * frame.size()) + " bytes queued"),
            std::string::npos)
      << pair.recorder->endText();
  EXPECT_FALSE(pair.peer->open());
}

TEST(Peer, EndsWithBadFrameOnAFrameOverItsMaximum) {
  PeerPair pair({.maxFrameBytes = 1024});
  pair.start();
  asio::write(pair.raw, asio::buffer(encodeBye(std::string(2000, 'x'))));
  ASSERT_TRUE(pair.recorder->waitForEnd());
  EXPECT_EQ(pair.recorder->end(), PeerEnd::BadFrame);
  EXPECT_NE(pair.recorder->endText().find("exceeds the maximum of 1024"), std::string::npos)
      << pair.recorder->endText();
  EXPECT_EQ(pair.recorder->frames(), 0u);
}

TEST(Peer, EndsWithConnectionLostWhenTheOtherEndCloses) {
  PeerPair pair;
  pair.start();
  asio::write(pair.raw, asio::buffer(encodeBye("last words")));
  pair.raw.close();
  ASSERT_TRUE(pair.recorder->waitForEnd());
  EXPECT_EQ(pair.recorder->end(), PeerEnd::ConnectionLost);
  EXPECT_EQ(pair.recorder->reasons(), std::vector<std::string>{"last words"});
}

TEST(Peer, DeliversNothingMoreAfterTheHandlerCloses) {
  PeerPair pair;
  pair.recorder->also = [&](const Envelope&) { pair.peer->close(); };
  pair.start();
  // Both frames in one write: they are decoded from the same read.
  auto bytes = encodeBye("first");
  const auto second = encodeBye("second");
  bytes.insert(bytes.end(), second.begin(), second.end());
  asio::write(pair.raw, asio::buffer(bytes));
  ASSERT_TRUE(pair.recorder->waitForFrames(1));
  // The raw side sees the connection closed: nothing else can arrive.
  std::array<uint8_t, 16> buf;
  boost::system::error_code ec;
  while (!ec) pair.raw.read_some(asio::buffer(buf), ec);
  EXPECT_EQ(pair.recorder->reasons(), std::vector<std::string>{"first"});
  EXPECT_EQ(pair.recorder->ends(), 0);  // close() is not reported as an end
}

TEST(Peer, HandsABadWelcomeToValidateWelcomeWhichNamesTheField) {
  PeerPair pair;
  std::promise<std::string> refusal;
  pair.recorder->also = [&](const Envelope& e) {
    dispatchPayload(e, Overloaded{[&](const Welcome& w) {
                                    try {
                                      validateWelcome(w);
                                      refusal.set_value("accepted");
                                    } catch (const InputError& error) {
                                      refusal.set_value(error.what());
                                      pair.peer->close();
                                    }
                                  },
                                  [](Payload) {}});
  };
  pair.start();
  WelcomeT w = goodWelcome();
  w.grid->cell_size = std::make_unique<Vec3f>(0.0f, 3.0f, 4.0f);
  asio::write(pair.raw, asio::buffer(encodeMessage(std::move(w))));
  std::future<std::string> answer = refusal.get_future();
  ASSERT_EQ(answer.wait_for(std::chrono::seconds(10)), std::future_status::ready);
  const std::string text = answer.get();
  EXPECT_NE(text.find("Welcome.grid.cell_size"), std::string::npos) << text;
  std::array<uint8_t, 16> buf;
  boost::system::error_code ec;
  while (!ec) pair.raw.read_some(asio::buffer(buf), ec);  // closed by the handler
}

}  // namespace
}  // namespace vistream::wire
