#include "common/core/progress.h"

#include <unistd.h>

#include <cstdio>

namespace vistream {

ProgressBar::ProgressBar(std::string label, uint64_t total)
    : label_(std::move(label)),
      total_(total),
      enabled_(isatty(fileno(stderr)) != 0),
      start_(std::chrono::steady_clock::now()),
      lastDraw_(start_) {}

ProgressBar::~ProgressBar() {
  finish();
}

void ProgressBar::advance(uint64_t n) {
  done_.fetch_add(n, std::memory_order_relaxed);
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  std::unique_lock lock(drawMutex_, std::try_to_lock);
  if (!lock.owns_lock() || now - lastDraw_ < std::chrono::milliseconds(100)) return;
  lastDraw_ = now;
  draw(false);
}

void ProgressBar::finish() {
  if (finished_) return;
  finished_ = true;
  if (!enabled_) return;
  std::lock_guard lock(drawMutex_);
  draw(true);
}

void ProgressBar::draw(bool final) {
  constexpr int kWidth = 30;
  const uint64_t done = std::min<uint64_t>(done_.load(), total_);
  const double frac = total_ ? double(done) / double(total_) : 1.0;
  const double secs =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const int filled = int(frac * kWidth);
  std::string bar(size_t(filled), '#');
  bar.resize(kWidth, '.');
  const double eta = frac > 0 ? secs * (1.0 - frac) / frac : 0.0;
  std::fprintf(stderr, "\r%-20s [%s] %5.1f%% %llu/%llu %6.1fs elapsed %6.1fs left%s",
               label_.c_str(), bar.c_str(), frac * 100.0, (unsigned long long)done,
               (unsigned long long)total_, secs, eta, final ? "\n" : "");
  std::fflush(stderr);
}

}  // namespace vistream
