// The order in which the shared worker pool takes visibility work, and how
// much of it may wait. Jobs wait here, not in the pool: every submission
// posts one runner to the pool, and a runner takes the most urgent job
// waiting (or nothing, if that job was dropped meanwhile), so a job that
// arrives late can overtake a crowd.
//
// Urgency (WorkPriority): short jobs a client waits for first (rank
// Immediate: a face set that needs no visibility computation, encoding a
// batch), then a client's current cell (rank Current), then prefetch (rank
// Prefetch), then refinement (rank Refine); within a rank, the job due
// soonest (the time its client is expected to need it), then the oldest.
//
// Bounds: at most `maxDroppable` jobs of rank Prefetch or Refine wait; a new
// one beyond that drops the least urgent waiting (its `dropped` callback
// runs, so its requester can ask again later) or is itself dropped if it is
// the least urgent. Immediate and current-cell jobs are never dropped for
// the bound: each session has at most a few, so sessions bound them. abandon() drops
// everything waiting, whatever its rank (each `dropped` runs), and refuses
// later submissions: a stopping server.
//
// Thread safety: every member may be called from any thread. Callbacks
// (`run`, `dropped`) are called without the queue's lock held.
#pragma once

#include <boost/asio/post.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <tuple>

namespace vistream {

struct WorkPriority {
  enum Rank : uint8_t { Immediate = 0, Current = 1, Prefetch = 2, Refine = 3 };
  Rank rank = Current;
  double dueS = 0.0;  // when the client is expected to need it (any clock, one per server)

  // Strictly more urgent.
  bool before(const WorkPriority& o) const {
    return std::tie(rank, dueS) < std::tie(o.rank, o.dueS);
  }
};

class WorkQueue {
 public:
  using Clock = std::chrono::steady_clock;
  using JobId = uint64_t;

  explicit WorkQueue(size_t maxDroppable = 64) : maxDroppable_(maxDroppable ? maxDroppable : 1) {}

  // Queues `run` and posts a runner to `executor`. Returns the job's ID, or 0
  // when the queue has been abandoned (nothing is queued or called).
  template <class Executor>
  JobId submit(Executor executor, WorkPriority priority, std::function<void()> run,
               std::function<void()> dropped = {}) {
    std::function<void()> droppedNow;
    JobId id = 0;
    {
      std::lock_guard lock(mutex_);
      if (abandoned_) return 0;
      id = nextId_++;
      insert(id, Job{priority, Clock::now(), std::move(run), std::move(dropped)});
      droppedNow = dropExcess();
    }
    if (droppedNow) droppedNow();
    boost::asio::post(executor, [this] { runNext(); });
    return id;
  }

  // Makes a waiting job at least as urgent as `priority` (another requester
  // joined it). False if it no longer waits (running, done or dropped).
  bool raise(JobId id, WorkPriority priority);

  // Drops every waiting job (their `dropped` callbacks run, on this thread)
  // and refuses later submissions. Runners already posted find nothing to do.
  void abandon();

  struct Load {
    size_t waiting = 0;           // jobs of every rank
    size_t waitingCurrent = 0;    // current-cell jobs
    size_t waitingDroppable = 0;  // prefetch and refinement jobs (not immediate ones)
    double oldestCurrentS = 0;    // how long the oldest current-cell job has waited
    uint64_t dropped = 0;         // jobs dropped so far for the bound
  };
  Load load() const;
  // Whether the workers have fallen behind: a current-cell job has waited
  // longer than `lagS`, or more current-cell jobs wait than
  // `maxWaitingCurrent` (prefetch has its own bound; immediate jobs are
  // short and not counted). Prefetch backs off while it holds.
  bool behind(double lagS, size_t maxWaitingCurrent) const;

 private:
  struct Job {
    WorkPriority priority;
    Clock::time_point queued;
    std::function<void()> run, dropped;
  };
  // Order: urgency, then age (the ID grows with submissions).
  using Key = std::tuple<uint8_t, double, JobId>;
  static Key keyOf(JobId id, const WorkPriority& p) { return {uint8_t(p.rank), p.dueS, id}; }

  static bool droppable(const WorkPriority& p) { return p.rank >= WorkPriority::Prefetch; }
  void insert(JobId id, Job job);
  // Over the bound: removes the least urgent droppable job and returns its
  // `dropped` callback (to be called once the lock is released).
  std::function<void()> dropExcess();
  void runNext();

  const size_t maxDroppable_;
  mutable std::mutex mutex_;  // guards everything below
  bool abandoned_ = false;
  JobId nextId_ = 1;
  std::map<Key, Job> jobs_;       // waiting, most urgent first
  std::map<JobId, Key> keys_;     // each waiting job's place in jobs_
  std::map<JobId, Key> current_;  // the waiting current-cell jobs, oldest first
  size_t droppable_ = 0;          // waiting jobs of rank Prefetch or Refine
  uint64_t droppedCount_ = 0;
};

}  // namespace vistream
