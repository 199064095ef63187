// Shared presence: the users of every server replica, so that users on one
// replica see the avatars of users on another (issue 17). Redis pub/sub
// carries it (redis-server from Debian, hiredis as the client); nothing
// else is shared between replicas, and visibility filtering stays with each
// receiving replica (StreamServer's avatar update).
//
// The conversation: each replica publishes, with every avatar update, a
// whole snapshot of its placed users on one channel per scene
// (`vistream:presence:<scene fingerprint, hex>`), and subscribes to the same
// channel. A snapshot replaces the previous one of that replica, so users
// missing from it have departed; a replica silent for `staleAfterS` is gone
// with all its users. Lost messages therefore cost nothing but delay.
//
// The message, JSON (readable with `redis-cli SUBSCRIBE`):
//   {"v":1,"replica":R,"sent_us":T,"users":[[id,x,y,z,yaw,pitch,speed,gait,phase],...]}
// R: the publisher's replica tag (1..255); T: its wall clock when sent
// (microseconds since the epoch; the receiver's fan-out latency); positions
// in the scene's local frame (metres), angles in degrees, speed in m/s,
// gait as wire::AvatarGait, phase in seconds. A message that does not parse
// or breaks these rules is counted and dropped (logged at a bounded rate).
//
// Session IDs are unique across replicas: a replica takes a tag from Redis
// (`INCR vistream:presence:<fingerprint>:replicas`, 1..255) and its session
// IDs carry it in their top 8 bits (StreamServer); without Redis at start
// it picks a random tag and says so.
//
// Losing Redis: the replica keeps serving its own users, logs the loss once,
// retries with backoff (0.2 s doubling to 2 s) and logs its return. Remote
// users go stale and depart meanwhile.
//
// Threads: one publishing thread (the newest snapshot waits; older unsent
// ones are dropped) and one subscribing thread; every public member is
// thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <glm/glm.hpp>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "server/stream/latency_histogram.h"

namespace vistream {

struct RedisAddress {
  std::string host;
  uint16_t port = 6379;
};
// `redis://host[:port]` (port 6379 when absent); throws InputError naming
// what is wrong.
RedisAddress parseRedisUrl(const std::string& url);

// One user as presence carries it.
struct PresenceUser {
  uint32_t id = 0;
  glm::dvec3 position{0.0};  // the eye, local frame
  float yawDeg = 0.0f, pitchDeg = 0.0f, speedMps = 0.0f;
  uint8_t gait = 0;
  float phaseS = 0.0f;
};

// The message of one replica's snapshot (see the format above); parse
// returns nothing and sets `error` for a message that breaks the rules.
std::string encodePresence(uint8_t replica, int64_t sentMicros,
                           const std::vector<PresenceUser>& users);
struct PresenceMessage {
  uint8_t replica = 0;
  int64_t sentMicros = 0;
  std::vector<PresenceUser> users;
};
std::optional<PresenceMessage> parsePresence(const std::string& text, std::string& error);

class RedisPresence {
 public:
  struct Options {
    RedisAddress redis;
    uint64_t sceneFingerprint = 0;  // names the channel: replicas of one scene only
    double staleAfterS = 3.0;       // a replica silent this long is gone
    double connectTimeoutS = 1.0;
  };
  // Takes the replica tag (see above; blocks at most connectTimeoutS) and
  // starts the two threads.
  explicit RedisPresence(Options options);
  ~RedisPresence();  // stops and joins the threads
  RedisPresence(const RedisPresence&) = delete;
  RedisPresence& operator=(const RedisPresence&) = delete;

  uint8_t replicaTag() const { return tag_; }
  const std::string& channel() const { return channel_; }

  // This replica's users now (a whole snapshot); sent off the caller's
  // thread, the newest only.
  void publish(std::vector<PresenceUser> users);

  // The users of other replicas heard from within staleAfterS, and the IDs
  // of those that departed (left a snapshot, or their replica went silent)
  // since the previous call.
  struct Remote {
    std::vector<PresenceUser> users;
    std::vector<uint32_t> departed;
  };
  Remote remote();

  struct Counters {
    uint64_t published = 0, received = 0, malformed = 0, lost = 0;
    size_t remoteReplicas = 0, remoteUsers = 0;
    bool connected = false;  // both connections up now
  };
  Counters counters() const;
  // Publish to receive, over Redis (wall clocks of the two replicas).
  const LatencyHistogram& latency() const { return latency_; }
  // Quantiles of the most recent latencies (seconds; nothing before the first).
  std::optional<double> latencyQuantile(double q) const;

 private:
  struct Connection;
  void publishLoop();
  void subscribeLoop();
  void onMessage(const std::string& text);
  void setUp(bool publisher, bool up);
  bool sleepUnlessStopping(std::chrono::milliseconds d);

  Options options_;
  std::string channel_;
  uint8_t tag_ = 0;
  std::atomic<bool> stopping_{false};
  mutable std::mutex
      mutex_;  // guards pending_, replicas_, departed_, samples_, publishUp_, subscribeUp_
  std::condition_variable wake_;
  std::optional<std::string> pending_;
  struct Replica {
    std::chrono::steady_clock::time_point heard;
    std::vector<PresenceUser> users;
  };
  std::map<uint8_t, Replica> replicas_;
  std::vector<uint32_t> departed_;
  std::vector<double> samples_;  // the most recent latencies, a ring
  size_t nextSample_ = 0;
  bool publishUp_ = false, subscribeUp_ = false, everUp_ = false;
  LatencyHistogram latency_;
  std::atomic<uint64_t> published_{0}, received_{0}, malformed_{0}, lost_{0};
  std::thread publisher_, subscriber_;
};

}  // namespace vistream
