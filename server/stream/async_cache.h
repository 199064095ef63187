// A bounded LRU cache whose values are computed once, off the caller's
// thread: the first request for a key posts the computation to an executor
// (the worker pool), later requests for the same key wait for that one
// computation, and every waiter's callback is invoked (on the worker thread
// that finished it) with the shared, immutable value. At most `capacity`
// finished values, costing at most `maxCost` together (by the cost function,
// e.g. bytes), are kept; the least recently used is dropped first.
//
// Cancellation: a request may carry an Interest (a token its requester
// holds). A computation that has not started when every waiter's interest
// has expired is not run at all: the entry is dropped and no callback is
// invoked (the requester, having let go of its interest, no longer waits).
// A computation that has started runs to the end and is cached. Requests
// without an interest are never cancelled. This is what bounds the work a
// client can leave behind on the shared pool: a session that moves on or
// closes drops its interests, and its queued computations cost a lock each.
//
// Errors: a computation that throws caches nothing; its waiters are called
// with a null pointer and the next request computes again.
//
// Priorities: given a WorkQueue (work_queue.h) at construction, computations
// wait there instead of being posted straight to the executor, in order of
// the most urgent request for them (a request joining a waiting computation
// raises it). When the queue drops a waiting computation for its bound, the
// entry is forgotten and each waiter's `dropped` callback (if any) runs
// instead of `done`: the requester may ask again later.
//
// Thread safety: every member may be called from any thread.
#pragma once

#include <atomic>
#include <boost/asio/post.hpp>
#include <cstdint>
#include <functional>
#include <limits>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "server/stream/work_queue.h"

namespace vistream {

// A requester's token: while some copy lives, the requester still wants the
// result. Drop every copy to cancel.
using Interest = std::shared_ptr<const int>;
inline Interest makeInterest() {
  return std::make_shared<const int>(0);
}

template <class Key, class Value, class Hash = std::hash<Key>>
class AsyncCache {
 public:
  using Ptr = std::shared_ptr<const Value>;
  using Callback = std::function<void(Ptr)>;
  using Compute = std::function<Value(const Key&)>;
  // Called with the key and the exception's message when a computation throws.
  using OnError = std::function<void(const Key&, const char*)>;

  using Cost = std::function<size_t(const Value&)>;

  AsyncCache(size_t capacity, Compute compute, OnError onError = {},
             size_t maxCost = std::numeric_limits<size_t>::max(), Cost cost = {},
             WorkQueue* queue = nullptr)
      : capacity_(capacity ? capacity : 1),
        maxCost_(maxCost),
        compute_(std::move(compute)),
        onError_(std::move(onError)),
        cost_(std::move(cost)),
        queue_(queue) {}

  // Whether the value is cached (not counted as a use).
  bool contains(const Key& key) const {
    std::lock_guard lock(mutex_);
    auto it = entries_.find(key);
    return it != entries_.end() && it->second.value != nullptr;
  }

  // The value if it is cached (counts as a hit and a use), else null.
  Ptr find(const Key& key) {
    std::lock_guard lock(mutex_);
    auto it = entries_.find(key);
    if (it == entries_.end() || !it->second.value) return nullptr;
    touch(it->second);
    ++hits_;
    return it->second.value;
  }

  // Calls `done` with the value: at once (on this thread) if cached, else
  // when the computation posted to `executor` finishes. With an `interest`,
  // the request lapses once the interest has expired (see above).
  // With a WorkQueue, the computation waits there with `priority` (raised if
  // a more urgent request joins it), and `dropped` replaces `done` should the
  // queue drop it.
  template <class Executor>
  void get(const Key& key, Executor executor, Callback done, const Interest& interest = nullptr,
           WorkPriority priority = {}, std::function<void()> dropped = {}) {
    std::unique_lock lock(mutex_);
    auto it = entries_.find(key);
    if (it != entries_.end() && it->second.value) {
      touch(it->second);
      ++hits_;
      Ptr v = it->second.value;
      lock.unlock();
      done(std::move(v));
      return;
    }
    ++misses_;
    Waiter w{std::move(done), interest, interest == nullptr, std::move(dropped)};
    if (it != entries_.end()) {  // queued or being computed
      it->second.waiters.push_back(std::move(w));
      if (queue_ && it->second.job && priority.before(it->second.priority)) {
        it->second.priority = priority;
        const WorkQueue::JobId job = it->second.job;
        lock.unlock();
        queue_->raise(job, priority);
      }
      return;
    }
    Entry& e = entries_[key];
    e.waiters.push_back(std::move(w));
    e.priority = priority;
    if (!queue_) {
      lock.unlock();
      boost::asio::post(executor, [this, key] { run(key); });
      return;
    }
    // Submitted without the lock: a submission may drop another waiting
    // computation, whose onDropped takes the lock.
    lock.unlock();
    const WorkQueue::JobId job = queue_->submit(
        executor, priority, [this, key] { run(key); }, [this, key] { onDropped(key); });
    std::vector<Waiter> abandoned;  // destroyed after the lock: they may hold sessions
    lock.lock();
    auto again = entries_.find(key);
    if (again == entries_.end() || again->second.value || again->second.running) return;
    if (job != 0) {
      again->second.job = job;  // unless it already ran or was dropped (above)
    } else {                    // the queue was abandoned: nobody will compute it
      abandoned.swap(again->second.waiters);
      entries_.erase(again);
      lock.unlock();
    }
  }

  uint64_t hits() const { return hits_; }
  uint64_t misses() const { return misses_; }
  uint64_t computed() const { return computed_; }
  // Computations dropped before they started because nobody waited any more.
  uint64_t cancelled() const { return cancelled_; }
  // Computations the work queue dropped for its bound.
  uint64_t dropped() const { return dropped_; }
  size_t cost() const {
    std::lock_guard lock(mutex_);
    return totalCost_;
  }
  size_t size() const {
    std::lock_guard lock(mutex_);
    return lru_.size();
  }

 private:
  struct Waiter {
    Callback done;
    std::weak_ptr<const int> interest;
    bool unconditional = false;
    std::function<void()> dropped;
    bool wanted() const { return unconditional || !interest.expired(); }
  };
  struct Entry {
    Ptr value;
    size_t cost = 0;
    bool running = false;
    WorkQueue::JobId job = 0;  // while waiting in the queue
    WorkPriority priority;     // the most urgent request's
    std::vector<Waiter> waiters;
    typename std::list<Key>::iterator position;
  };
  void touch(Entry& e) { lru_.splice(lru_.begin(), lru_, e.position); }

  void onDropped(const Key& key) {
    std::vector<Waiter> waiters;
    {
      std::lock_guard guard(mutex_);
      auto it = entries_.find(key);
      if (it == entries_.end() || it->second.value || it->second.running) return;
      waiters.swap(it->second.waiters);
      entries_.erase(it);
      ++dropped_;
    }
    for (auto& w : waiters)
      if (w.dropped && w.wanted()) w.dropped();
  }

  void run(const Key& key) {
    std::vector<Waiter> dropped;  // destroyed after the lock: they may hold sessions
    {
      std::lock_guard guard(mutex_);
      auto it = entries_.find(key);
      if (it == entries_.end() || it->second.value || it->second.running) return;
      Entry& entry = it->second;
      bool wanted = false;
      for (const Waiter& w : entry.waiters) wanted = wanted || w.wanted();
      if (!wanted) {
        dropped.swap(entry.waiters);
        entries_.erase(it);
        ++cancelled_;
        return;
      }
      entry.running = true;
      entry.job = 0;
    }
    Ptr value;
    try {
      value = std::make_shared<const Value>(compute_(key));
    } catch (const std::exception& e) {
      if (onError_) onError_(key, e.what());
    } catch (...) {
      if (onError_) onError_(key, "an exception of unknown type");
    }
    std::vector<Waiter> waiters;
    {
      std::lock_guard guard(mutex_);
      auto it = entries_.find(key);
      waiters.swap(it->second.waiters);
      if (!value) {
        entries_.erase(it);
      } else {
        Entry& entry = it->second;
        entry.value = value;
        entry.cost = cost_ ? cost_(*value) : 1;
        entry.running = false;
        totalCost_ += entry.cost;
        lru_.push_front(key);
        entry.position = lru_.begin();
        ++computed_;
        // The newest value stays even if it alone costs more than the limit.
        while (lru_.size() > capacity_ || (totalCost_ > maxCost_ && lru_.size() > 1)) {
          auto victim = entries_.find(lru_.back());
          totalCost_ -= victim->second.cost;
          entries_.erase(victim);
          lru_.pop_back();
        }
      }
    }
    for (auto& w : waiters) w.done(value);
  }

  size_t capacity_, maxCost_;
  Compute compute_;
  OnError onError_;
  Cost cost_;
  WorkQueue* queue_;
  mutable std::mutex mutex_;  // guards entries_, lru_ and totalCost_
  size_t totalCost_ = 0;      // of the finished values kept
  std::unordered_map<Key, Entry, Hash> entries_;
  std::list<Key> lru_;
  std::atomic<uint64_t> hits_{0}, misses_{0}, computed_{0}, cancelled_{0}, dropped_{0};
};

}  // namespace vistream
