#include "server/stream/presence.h"

#include <hiredis/hiredis.h>
#include <poll.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

#include "common/core/error.h"
#include "common/core/log.h"

namespace vistream {

namespace {

using Clock = std::chrono::steady_clock;

timeval toTimeval(double seconds) {
  const auto us = int64_t(std::max(0.0, seconds) * 1e6);
  return timeval{time_t(us / 1000000), suseconds_t(us % 1000000)};
}

int64_t wallMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

constexpr size_t kLatencySamples = 4096;
constexpr size_t kMaxUsersPerMessage = 1u << 16;  // a replica's whole population, bounded

// The bounded-rate log of malformed messages (any process may publish on the channel).
LogLimiter& malformedLog() {
  static LogLimiter limiter("malformed presence message");
  return limiter;
}

}  // namespace

RedisAddress parseRedisUrl(const std::string& url) {
  constexpr std::string_view scheme = "redis://";
  if (url.rfind(scheme, 0) != 0)
    throwInputError("--presence {}: expected redis://host[:port]", url);
  std::string rest = url.substr(scheme.size());
  if (!rest.empty() && rest.back() == '/') rest.pop_back();
  RedisAddress a;
  const size_t colon = rest.rfind(':');
  a.host = colon == std::string::npos ? rest : rest.substr(0, colon);
  if (a.host.empty() || a.host.find_first_of("/@?") != std::string::npos)
    throwInputError("--presence {}: expected redis://host[:port] (no user, path or options)", url);
  if (colon != std::string::npos) {
    const std::string port = rest.substr(colon + 1);
    unsigned value = 0;
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
    if (ec != std::errc() || end != port.data() + port.size() || value == 0 || value > 65535)
      throwInputError("--presence {}: the port '{}' is not a number in 1..65535", url, port);
    a.port = uint16_t(value);
  }
  return a;
}

std::string encodePresence(uint8_t replica, int64_t sentMicros,
                           const std::vector<PresenceUser>& users) {
  nlohmann::json list = nlohmann::json::array();
  for (const PresenceUser& u : users)
    list.push_back({u.id, u.position.x, u.position.y, u.position.z, u.yawDeg, u.pitchDeg,
                    u.speedMps, u.gait, u.phaseS});
  return nlohmann::json{{"v", 1}, {"replica", replica}, {"sent_us", sentMicros}, {"users", list}}
      .dump();
}

std::optional<PresenceMessage> parsePresence(const std::string& text, std::string& error) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  auto bad = [&](std::string why) -> std::optional<PresenceMessage> {
    error = std::move(why);
    return std::nullopt;
  };
  if (j.is_discarded() || !j.is_object()) return bad("not a JSON object");
  if (!j.contains("v") || j["v"] != 1) return bad("\"v\" is not 1");
  const auto& replica = j.value("replica", nlohmann::json());
  if (!replica.is_number_unsigned() || replica.get<uint64_t>() < 1 || replica.get<uint64_t>() > 255)
    return bad("\"replica\" is not a number in 1..255");
  const auto& sent = j.value("sent_us", nlohmann::json());
  if (!sent.is_number_integer()) return bad("\"sent_us\" is not an integer");
  const auto& users = j.value("users", nlohmann::json());
  if (!users.is_array()) return bad("\"users\" is not an array");
  if (users.size() > kMaxUsersPerMessage)
    return bad(
        fmt::format("\"users\" holds {} users, more than {}", users.size(), kMaxUsersPerMessage));
  PresenceMessage m;
  m.replica = uint8_t(replica.get<uint64_t>());
  m.sentMicros = sent.get<int64_t>();
  m.users.reserve(users.size());
  for (size_t i = 0; i < users.size(); ++i) {
    const auto& u = users[i];
    if (!u.is_array() || u.size() != 9 || !u[0].is_number_unsigned() ||
        u[0].get<uint64_t>() > UINT32_MAX || !u[7].is_number_unsigned() || u[7].get<uint64_t>() > 2)
      return bad(fmt::format("user {} is not [id,x,y,z,yaw,pitch,speed,gait,phase]", i));
    for (size_t k = 1; k <= 8; ++k)
      if (!u[k].is_number() || !std::isfinite(u[k].get<double>()))
        return bad(fmt::format("user {}: field {} is not a finite number", i, k));
    PresenceUser p;
    p.id = uint32_t(u[0].get<uint64_t>());
    p.position = {u[1].get<double>(), u[2].get<double>(), u[3].get<double>()};
    p.yawDeg = u[4].get<float>();
    p.pitchDeg = u[5].get<float>();
    p.speedMps = u[6].get<float>();
    p.gait = uint8_t(u[7].get<uint64_t>());
    p.phaseS = u[8].get<float>();
    m.users.push_back(p);
  }
  return m;
}

// One hiredis connection, freed with its owner.
struct RedisPresence::Connection {
  redisContext* c = nullptr;
  ~Connection() { reset(); }
  void reset() {
    if (c) redisFree(c);
    c = nullptr;
  }
  // Connects (with a timeout for the connect and every command); false with
  // `error` set if it cannot.
  bool open(const RedisAddress& a, double timeoutS, std::string& error) {
    reset();
    c = redisConnectWithTimeout(a.host.c_str(), a.port, toTimeval(timeoutS));
    if (!c || c->err) {
      error = c ? c->errstr : "cannot allocate a Redis context";
      reset();
      return false;
    }
    redisSetTimeout(c, toTimeval(timeoutS));
    return true;
  }
  // A command's reply, or null (error set; the connection is then unusable).
  template <class... Args>
  redisReply* command(std::string& error, const char* format, Args... args) {
    auto* reply = static_cast<redisReply*>(redisCommand(c, format, args...));
    if (!reply) error = c->errstr;
    if (reply && reply->type == REDIS_REPLY_ERROR) {
      error = std::string(reply->str, reply->len);
      freeReplyObject(reply);
      return nullptr;
    }
    return reply;
  }
};

RedisPresence::RedisPresence(Options options) : options_(std::move(options)) {
  channel_ = fmt::format("vistream:presence:{:016x}", options_.sceneFingerprint);
  Connection once;
  std::string error;
  if (once.open(options_.redis, options_.connectTimeoutS, error)) {
    const std::string key = channel_ + ":replicas";
    if (redisReply* r = once.command(error, "INCR %s", key.c_str())) {
      if (r->type == REDIS_REPLY_INTEGER) tag_ = uint8_t(uint64_t(r->integer - 1) % 255 + 1);
      freeReplyObject(r);
    }
  }
  if (tag_ == 0) {
    std::random_device random;
    tag_ = uint8_t(random() % 255 + 1);
    spdlog::warn(
        "presence: Redis at {}:{} is not reachable ({}); replica tag {} chosen at random, "
        "serving local users until Redis answers",
        options_.redis.host, options_.redis.port, error, tag_);
  } else {
    spdlog::info("presence: replica {} on channel {} of Redis at {}:{}", tag_, channel_,
                 options_.redis.host, options_.redis.port);
  }
  publisher_ = std::thread([this] { publishLoop(); });
  subscriber_ = std::thread([this] { subscribeLoop(); });
}

RedisPresence::~RedisPresence() {
  stopping_ = true;
  wake_.notify_all();
  publisher_.join();
  subscriber_.join();
}

void RedisPresence::publish(std::vector<PresenceUser> users) {
  std::string message = encodePresence(tag_, wallMicros(), users);
  {
    std::lock_guard lock(mutex_);
    pending_ = std::move(message);
  }
  wake_.notify_all();
}

bool RedisPresence::sleepUnlessStopping(std::chrono::milliseconds d) {
  std::unique_lock lock(mutex_);
  wake_.wait_for(lock, d, [this] { return stopping_.load(); });
  return !stopping_;
}

// Both connections' state; the loss and the return are logged once each
// (by whichever connection notices first).
void RedisPresence::setUp(bool publisher, bool up) {
  std::lock_guard lock(mutex_);
  const bool before = publishUp_ && subscribeUp_;
  (publisher ? publishUp_ : subscribeUp_) = up;
  const bool after = publishUp_ && subscribeUp_;
  if (before && !after) {
    ++lost_;
    spdlog::warn("presence: lost Redis at {}:{}; serving local users only, retrying",
                 options_.redis.host, options_.redis.port);
  } else if (!before && after) {
    spdlog::info("presence: {} Redis at {}:{}", everUp_ ? "rejoined" : "joined",
                 options_.redis.host, options_.redis.port);
    everUp_ = true;
  }
}

void RedisPresence::publishLoop() {
  Connection redis;
  std::chrono::milliseconds backoff(200);
  while (!stopping_) {
    std::string error;
    if (!redis.c) {
      if (!redis.open(options_.redis, options_.connectTimeoutS, error)) {
        setUp(true, false);
        spdlog::debug("presence: publish connection: {}", error);
        if (!sleepUnlessStopping(backoff)) return;
        backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
        std::lock_guard lock(mutex_);
        pending_.reset();  // stale by now; the next snapshot goes
        continue;
      }
      backoff = std::chrono::milliseconds(200);
      setUp(true, true);
    }
    std::string message;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || pending_.has_value(); });
      if (stopping_) return;
      message = std::move(*pending_);
      pending_.reset();
    }
    if (redisReply* r = redis.command(error, "PUBLISH %s %b", channel_.c_str(), message.data(),
                                      message.size())) {
      freeReplyObject(r);
      ++published_;
    } else {
      spdlog::debug("presence: PUBLISH failed: {}", error);
      redis.reset();
      setUp(true, false);
    }
  }
}

void RedisPresence::subscribeLoop() {
  Connection redis;
  std::chrono::milliseconds backoff(200);
  while (!stopping_) {
    std::string error;
    redisReply* confirm = nullptr;
    if (redis.open(options_.redis, options_.connectTimeoutS, error))
      confirm = redis.command(error, "SUBSCRIBE %s", channel_.c_str());
    if (!confirm) {
      redis.reset();
      setUp(false, false);
      spdlog::debug("presence: subscribe connection: {}", error);
      if (!sleepUnlessStopping(backoff)) return;
      backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
      continue;
    }
    freeReplyObject(confirm);
    backoff = std::chrono::milliseconds(200);
    setUp(false, true);
    // Messages as they come; a poll with a short timeout so that stopping
    // is noticed, and a read error or a closed socket ends the connection.
    bool alive = true;
    while (alive && !stopping_) {
      void* raw = nullptr;
      if (redisGetReplyFromReader(redis.c, &raw) != REDIS_OK) break;
      if (raw) {
        auto* reply = static_cast<redisReply*>(raw);
        if (reply->type == REDIS_REPLY_ARRAY && reply->elements == 3 &&
            reply->element[0]->type == REDIS_REPLY_STRING &&
            std::string(reply->element[0]->str, reply->element[0]->len) == "message" &&
            reply->element[2]->type == REDIS_REPLY_STRING)
          onMessage(std::string(reply->element[2]->str, reply->element[2]->len));
        freeReplyObject(reply);
        continue;
      }
      pollfd p{redis.c->fd, POLLIN, 0};
      const int ready = ::poll(&p, 1, 200);
      if (ready < 0 && errno != EINTR) alive = false;
      if (ready > 0 && redisBufferRead(redis.c) != REDIS_OK) alive = false;
    }
    if (stopping_) return;
    spdlog::debug("presence: subscription ended: {}",
                  redis.c && redis.c->err ? redis.c->errstr : "");
    redis.reset();
    setUp(false, false);
  }
}

void RedisPresence::onMessage(const std::string& text) {
  std::string error;
  std::optional<PresenceMessage> m = parsePresence(text, error);
  if (!m) {
    ++malformed_;
    malformedLog().warn("presence: a message on {} dropped: {}", channel_, error);
    return;
  }
  if (m->replica == tag_) return;  // our own
  ++received_;
  const double latency = double(wallMicros() - m->sentMicros) * 1e-6;
  latency_.observe(std::max(0.0, latency));
  std::lock_guard lock(mutex_);
  if (samples_.size() < kLatencySamples)
    samples_.push_back(latency);
  else
    samples_[nextSample_++ % kLatencySamples] = latency;
  Replica& r = replicas_[m->replica];
  std::set<uint32_t> now;
  for (const PresenceUser& u : m->users) now.insert(u.id);
  for (const PresenceUser& u : r.users)
    if (!now.count(u.id)) departed_.push_back(u.id);
  r.users = std::move(m->users);
  r.heard = Clock::now();
}

RedisPresence::Remote RedisPresence::remote() {
  Remote out;
  const auto now = Clock::now();
  std::lock_guard lock(mutex_);
  for (auto it = replicas_.begin(); it != replicas_.end();) {
    if (std::chrono::duration<double>(now - it->second.heard).count() > options_.staleAfterS) {
      for (const PresenceUser& u : it->second.users) departed_.push_back(u.id);
      it = replicas_.erase(it);
      continue;
    }
    out.users.insert(out.users.end(), it->second.users.begin(), it->second.users.end());
    ++it;
  }
  out.departed.swap(departed_);
  return out;
}

RedisPresence::Counters RedisPresence::counters() const {
  Counters c{published_, received_, malformed_, lost_};
  std::lock_guard lock(mutex_);
  c.remoteReplicas = replicas_.size();
  for (const auto& [tag, r] : replicas_) c.remoteUsers += r.users.size();
  c.connected = publishUp_ && subscribeUp_;
  return c;
}

std::optional<double> RedisPresence::latencyQuantile(double q) const {
  std::vector<double> v;
  {
    std::lock_guard lock(mutex_);
    v = samples_;
  }
  if (v.empty()) return std::nullopt;
  const size_t k = std::min(v.size() - 1, size_t(std::clamp(q, 0.0, 1.0) * double(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + ptrdiff_t(k), v.end());
  return v[k];
}

}  // namespace vistream
