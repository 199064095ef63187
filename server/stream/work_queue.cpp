#include "server/stream/work_queue.h"

namespace vistream {

void WorkQueue::insert(JobId id, Job job) {
  const Key key = keyOf(id, job.priority);
  if (job.priority.rank == WorkPriority::Current)
    current_[id] = key;
  else if (droppable(job.priority))
    ++droppable_;
  keys_[id] = key;
  jobs_.emplace(key, std::move(job));
}

std::function<void()> WorkQueue::dropExcess() {
  if (droppable_ <= maxDroppable_) return {};
  // The least urgent job is the last one; it is droppable, since at least
  // one droppable job waits and every droppable rank sorts after the others.
  auto last = std::prev(jobs_.end());
  const JobId id = std::get<2>(last->first);
  std::function<void()> dropped = std::move(last->second.dropped);
  jobs_.erase(last);
  keys_.erase(id);
  --droppable_;
  ++droppedCount_;
  return dropped;
}

bool WorkQueue::raise(JobId id, WorkPriority priority) {
  std::lock_guard lock(mutex_);
  auto k = keys_.find(id);
  if (k == keys_.end()) return false;
  auto j = jobs_.find(k->second);
  if (!priority.before(j->second.priority)) return true;
  Job job = std::move(j->second);
  jobs_.erase(j);
  keys_.erase(k);
  if (job.priority.rank == WorkPriority::Current)
    current_.erase(id);
  else if (droppable(job.priority))
    --droppable_;
  job.priority = priority;
  insert(id, std::move(job));
  return true;
}

void WorkQueue::abandon() {
  std::map<Key, Job> dropped;
  {
    std::lock_guard lock(mutex_);
    abandoned_ = true;
    dropped.swap(jobs_);
    keys_.clear();
    current_.clear();
    droppable_ = 0;
  }
  // Without the lock: a requester's callback may submit (refused now) or
  // release what it holds.
  for (auto& [key, job] : dropped)
    if (job.dropped) job.dropped();
}

void WorkQueue::runNext() {
  std::function<void()> run;
  {
    std::lock_guard lock(mutex_);
    if (jobs_.empty()) return;
    auto first = jobs_.begin();
    const JobId id = std::get<2>(first->first);
    if (first->second.priority.rank == WorkPriority::Current)
      current_.erase(id);
    else if (droppable(first->second.priority))
      --droppable_;
    run = std::move(first->second.run);
    jobs_.erase(first);
    keys_.erase(id);
  }
  run();
}

WorkQueue::Load WorkQueue::load() const {
  std::lock_guard lock(mutex_);
  Load l;
  l.waiting = jobs_.size();
  l.waitingCurrent = current_.size();
  l.waitingDroppable = droppable_;
  l.dropped = droppedCount_;
  if (!current_.empty()) {
    const Job& oldest = jobs_.at(current_.begin()->second);
    l.oldestCurrentS = std::chrono::duration<double>(Clock::now() - oldest.queued).count();
  }
  return l;
}

bool WorkQueue::behind(double lagS, size_t maxWaitingCurrent) const {
  const Load l = load();
  return l.oldestCurrentS > lagS || l.waitingCurrent > maxWaitingCurrent;
}

}  // namespace vistream
