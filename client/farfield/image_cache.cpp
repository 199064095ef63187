#include "client/farfield/image_cache.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/core/check.h"

namespace vistream {
namespace {
constexpr float kTwoPi = 6.28318530718f;
constexpr size_t kMaxTexels = size_t(1) << 26;  // 64 Mi texels, 512 MiB
}  // namespace

PanoramicCache::PanoramicCache(float pixelAngle, const PanoramicCacheOptions& options)
    : options_(options) {
  float texelAngle = pixelAngle / std::max(options.texelsPerPixel, 0.05f);
  maxSlope_ = std::clamp(options.maxSlope, 0.01f, 100.0f);
  // At most kMaxTexels: a tiny field of view on a huge image would otherwise
  // ask for a panorama of many gigabytes.
  const double wanted = double(kTwoPi) / texelAngle * 2.0 * maxSlope_ / texelAngle;
  if (wanted > double(kMaxTexels)) texelAngle *= float(std::sqrt(wanted / double(kMaxTexels)));
  columns_ = std::max(16, int(std::ceil(kTwoPi / texelAngle)));
  rows_ = std::max(4, int(std::ceil(2.0f * maxSlope_ / texelAngle)));
  clear();
}

void PanoramicCache::clear() {
  colours_.assign(size_t(columns_) * size_t(rows_), glm::u8vec3(0));
  texelRecord_.assign(colours_.size(), 0);
  records_.assign(1, Record{});
  records_[0].refs = uint32_t(colours_.size());
  free_.clear();
  current_ = 0;
}

int64_t PanoramicCache::texelOf(const glm::vec3& d) const {
  const float h = std::sqrt(d.x * d.x + d.z * d.z);
  if (!(h > 0.0f)) return -1;
  const float slope = d.y / h;
  if (!(std::abs(slope) < maxSlope_)) return -1;
  const float az = std::atan2(-d.x, -d.z);  // [-pi, pi]
  int u = int((az / kTwoPi + 0.5f) * float(columns_));
  u = ((u % columns_) + columns_) % columns_;
  const int v = std::clamp(int((slope / maxSlope_ * 0.5f + 0.5f) * float(rows_)), 0, rows_ - 1);
  return int64_t(v) * columns_ + u;
}

uint32_t PanoramicCache::openRecord(const glm::vec3& eye) {
  uint32_t r;
  if (!free_.empty()) {
    r = free_.back();
    free_.pop_back();
    records_[r] = Record{};
  } else {
    r = uint32_t(records_.size());
    records_.push_back(Record{});
  }
  records_[r].position = eye;
  return r;
}

void PanoramicCache::release(uint32_t r) {
  if (r != 0 && r != current_ && records_[r].refs == 0) free_.push_back(r);
}

CachePlanStats PanoramicCache::plan(const glm::vec3& eye, std::span<const int64_t> texels,
                                    size_t budget, float maxStale, std::vector<uint8_t>& trace,
                                    bool viewTurned) {
  if (current_ == 0 || glm::length(records_[current_].position - eye) > options_.recordSpacing) {
    const uint32_t old = current_;
    current_ = openRecord(eye);
    if (old != 0) release(old);
  }
  CachePlanStats s;
  s.candidates = texels.size();
  trace.assign(texels.size(), 0);
  touched_.clear();
  for (int64_t t : texels) {
    if (t < 0) continue;
    Record& r = records_[texelRecord_[size_t(t)]];
    if (r.count++ == 0) touched_.push_back(texelRecord_[size_t(t)]);
  }
  size_t must = 0;
  for (uint32_t id : touched_) {
    Record& r = records_[id];
    r.distance = id == 0 ? std::numeric_limits<float>::infinity() : glm::length(r.position - eye);
    if (r.distance > maxStale) must += r.count;
  }
  for (int64_t t : texels) must += t < 0;
  // Budgeted records: valid but not from here, farthest first.
  std::vector<uint32_t> ranked;
  for (uint32_t id : touched_)
    if (records_[id].distance <= maxStale && id != current_) ranked.push_back(id);
  std::sort(ranked.begin(), ranked.end(), [&](uint32_t a, uint32_t b) {
    return records_[a].distance != records_[b].distance
               ? records_[a].distance > records_[b].distance
               : a < b;
  });
  size_t left = budget > must ? budget - must : 0;
  // Per record: 0 = reuse, 1 = retrace all, n > 1 = retrace every n-th.
  if (partialStep_.size() < records_.size()) {
    partialStep_.resize(records_.size(), 0);
    partialSeen_.resize(records_.size(), 0);
  }
  s.thresholdDistance = std::numeric_limits<float>::infinity();
  for (uint32_t id : ranked) {
    const Record& r = records_[id];
    if (left == 0) {
      s.degraded = true;
      break;
    }
    s.thresholdDistance = r.distance;
    if (r.count <= left) {
      partialStep_[id] = 1;
      left -= r.count;
    } else {
      partialStep_[id] = uint32_t((r.count + left - 1) / left);
      left = 0;
      s.degraded = true;
    }
  }
  for (size_t i = 0; i < texels.size(); ++i) {
    const int64_t t = texels[i];
    if (t < 0) {
      trace[i] = 1;
      ++s.mustTrace;
      continue;
    }
    const uint32_t id = texelRecord_[size_t(t)];
    const Record& r = records_[id];
    if (r.distance > maxStale) {
      trace[i] = 1;
      ++s.mustTrace;
    } else if (options_.retraceEdges && (viewTurned || id != current_) && onEdge(t)) {
      trace[i] = 1;
      ++s.edges;
    } else if (partialStep_[id] != 0 && partialSeen_[id]++ % partialStep_[id] == 0) {
      trace[i] = 1;
      ++s.budgeted;
    } else {
      ++s.reused;
    }
  }
  for (uint32_t id : touched_) {
    records_[id].count = 0;
    partialStep_[id] = 0;
    partialSeen_[id] = 0;
  }
  return s;
}

bool PanoramicCache::onEdge(int64_t texel) const {
  const int u = int(texel % columns_), v = int(texel / columns_);
  const glm::u8vec3 c = colours_[size_t(texel)];
  const int64_t left = int64_t(v) * columns_ + (u + columns_ - 1) % columns_;
  const int64_t right = int64_t(v) * columns_ + (u + 1) % columns_;
  for (int64_t n :
       {left, right, v > 0 ? texel - columns_ : texel, v + 1 < rows_ ? texel + columns_ : texel})
    if (texelRecord_[size_t(n)] != 0 && colours_[size_t(n)] != c) return true;
  return false;
}

void PanoramicCache::store(int64_t texel, glm::u8vec3 colour) {
  VS_DCHECK(texel >= 0 && size_t(texel) < colours_.size());
  const uint32_t old = texelRecord_[size_t(texel)];
  colours_[size_t(texel)] = colour;
  if (old == current_) return;
  --records_[old].refs;
  texelRecord_[size_t(texel)] = current_;
  ++records_[current_].refs;
  release(old);
}

}  // namespace vistream
