// A bounded LRU cache whose values are computed once, off the caller's
// thread: the first request for a key posts the computation to an executor
// (the worker pool), later requests for the same key wait for that one
// computation, and every waiter's callback is invoked (on the worker thread
// that finished it) with the shared, immutable value. At most `capacity`
// finished values are kept; the least recently used is dropped first.
//
// Thread safety: every member may be called from any thread.
#pragma once

#include <boost/asio/post.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace vistream {

template <class Key, class Value, class Hash = std::hash<Key>>
class AsyncCache {
 public:
  using Ptr = std::shared_ptr<const Value>;
  using Callback = std::function<void(Ptr)>;
  using Compute = std::function<Value(const Key&)>;

  AsyncCache(size_t capacity, Compute compute) : capacity_(capacity ? capacity : 1), compute_(std::move(compute)) {}

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
  // when the computation posted to `executor` finishes.
  template <class Executor>
  void get(const Key& key, Executor executor, Callback done) {
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
    if (it != entries_.end()) {  // being computed
      it->second.waiters.push_back(std::move(done));
      return;
    }
    Entry& e = entries_[key];
    e.waiters.push_back(std::move(done));
    lock.unlock();
    boost::asio::post(executor, [this, key] {
      Ptr value = std::make_shared<const Value>(compute_(key));
      std::vector<Callback> waiters;
      {
        std::lock_guard guard(mutex_);
        Entry& entry = entries_[key];
        entry.value = value;
        waiters.swap(entry.waiters);
        lru_.push_front(key);
        entry.position = lru_.begin();
        ++computed_;
        while (lru_.size() > capacity_) {
          entries_.erase(lru_.back());
          lru_.pop_back();
        }
      }
      for (auto& w : waiters) w(value);
    });
  }

  uint64_t hits() const { return hits_; }
  uint64_t misses() const { return misses_; }
  uint64_t computed() const { return computed_; }
  size_t size() const {
    std::lock_guard lock(mutex_);
    return lru_.size();
  }

 private:
  struct Entry {
    Ptr value;
    std::vector<Callback> waiters;
    typename std::list<Key>::iterator position;
  };
  void touch(Entry& e) { lru_.splice(lru_.begin(), lru_, e.position); }

  size_t capacity_;
  Compute compute_;
  mutable std::mutex mutex_;
  std::unordered_map<Key, Entry, Hash> entries_;
  std::list<Key> lru_;
  std::atomic<uint64_t> hits_{0}, misses_{0}, computed_{0};
};

}  // namespace vistream
