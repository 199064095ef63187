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
  hitDistance_.assign(colours_.size(), std::numeric_limits<float>::infinity());
  hitTriangle_.assign(colours_.size(), kNoTexelHit);
  tileColumns_ = (columns_ + kTile - 1) / kTile;
  tileTraced_.assign(size_t(tileColumns_) * size_t((rows_ + kTile - 1) / kTile), 0);
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

void PanoramicCache::store(int64_t texel, glm::u8vec3 colour, float hitDistance,
                           uint32_t triangle) {
  VS_DCHECK(texel >= 0 && size_t(texel) < colours_.size());
  const uint32_t old = texelRecord_[size_t(texel)];
  colours_[size_t(texel)] = colour;
  hitDistance_[size_t(texel)] = hitDistance;
  hitTriangle_[size_t(texel)] = triangle;
  if (old == current_) return;
  if (old == 0) ++tileTraced_[tileOf(texel)];
  --records_[old].refs;
  texelRecord_[size_t(texel)] = current_;
  ++records_[current_].refs;
  release(old);
}

void PanoramicCache::forget(size_t texel) {
  const uint32_t old = texelRecord_[texel];
  if (old == 0) return;
  --tileTraced_[tileOf(int64_t(texel))];
  --records_[old].refs;
  texelRecord_[texel] = 0;
  ++records_[0].refs;
  release(old);
}

glm::vec3 PanoramicCache::texelDirection(int64_t texel) const {
  const int u = int(texel % columns_), v = int(texel / columns_);
  const float az = ((float(u) + 0.5f) / float(columns_) - 0.5f) * kTwoPi;
  const float slope = ((float(v) + 0.5f) / float(rows_) - 0.5f) * 2.0f * maxSlope_;
  return glm::normalize(glm::vec3(-std::sin(az), slope, -std::cos(az)));
}

namespace {

// A cone of directions (unit axis, half-angle) from the points of a ball
// (centre, radius), tested against a box through its bounding sphere.
struct Cone {
  glm::vec3 apex{0.0f};
  float apexRadius = 0.0f;
  glm::vec3 axis{0.0f, 0.0f, -1.0f};
  float halfAngle = 0.0f;

  // Whether some ray of the cone, leaving from some point of the ball, may
  // meet `box` at a distance below `within` metres. Conservative: rounding
  // and the bounding sphere only make it say yes more often.
  bool mayMeet(const Box3f& box, float within) const {
    const glm::vec3 q = glm::clamp(apex, box.lo, box.hi);
    const float nearest = glm::length(q - apex) - apexRadius;
    if (!(within > nearest * (1.0f - 1e-5f) - 1e-4f)) return false;
    const glm::vec3 w = box.center() - apex;
    const float L = glm::length(w);
    // The ball's radius moves the apex: the sphere grows by as much.
    const float R = 0.5f * glm::length(box.extent()) + apexRadius;
    if (L <= R * (1.0f + 1e-5f) + 1e-4f) return true;
    // theta <= halfAngle + beta, with sin(beta) = R / L, in cosines (both
    // sides in [0, pi] while halfAngle + beta is; beyond, every direction meets).
    const float sinBeta = std::min(1.0f, R / L), cosBeta = std::sqrt(1.0f - sinBeta * sinBeta);
    const float reach = halfAngle + 1e-4f;
    if (reach + std::asin(sinBeta) >= 3.14159f) return true;
    const float cosReach = std::cos(reach) * cosBeta - std::sin(reach) * sinBeta;
    return glm::dot(axis, w) / L >= cosReach - 1e-5f;
  }
};

}  // namespace

size_t PanoramicCache::invalidate(std::span<const Box3f> added, std::span<const uint8_t> removed,
                                  bool forgetImpostors) {
  // Angular half-size of a texel: half an azimuth step plus half a slope
  // step (a slope step spans at most as much elevation angle), with margin.
  const float azStep = kTwoPi / float(columns_), slopeStep = 2.0f * maxSlope_ / float(rows_);
  const float texelHalf = 0.5f * (azStep + slopeStep) * 1.01f + 1e-6f;
  // Texels are tested in tiles of kTile x kTile: a box no ray of the tile's
  // cone can meet from any of its records is skipped for all of them, and
  // tiles without a traced texel are skipped at once.
  size_t forgotten = 0;
  std::vector<const Box3f*> reach;
  for (int v0 = 0; v0 < rows_; v0 += kTile)
    for (int u0 = 0; u0 < columns_; u0 += kTile) {
      if (tileTraced_[size_t(v0 / kTile) * size_t(tileColumns_) + size_t(u0 / kTile)] == 0)
        continue;
      const int v1 = std::min(rows_, v0 + kTile), u1 = std::min(columns_, u0 + kTile);
      // Removed triangles first; the positions of the tile's records on the way.
      Box3f positions;
      for (int v = v0; v < v1; ++v)
        for (int u = u0; u < u1; ++u) {
          const size_t t = size_t(v) * size_t(columns_) + size_t(u);
          const uint32_t id = texelRecord_[t];
          if (id == 0) continue;
          const uint32_t hit = hitTriangle_[t];
          if ((hit != kNoTexelHit && hit < removed.size() && removed[hit]) ||
              (forgetImpostors && hit == kImpostorTexelHit)) {
            forget(t);
            ++forgotten;
            continue;
          }
          positions.extend(records_[id].position);
        }
      if (positions.empty() || added.empty()) continue;
      const int64_t centre = int64_t((v0 + v1) / 2) * columns_ + (u0 + u1) / 2;
      Cone tile{positions.center(), 0.5f * glm::length(positions.extent()) + options_.recordSpacing,
                texelDirection(centre), texelHalf * float(kTile + 1)};
      reach.clear();
      for (const Box3f& b : added)
        if (!b.empty() && tile.mayMeet(b, std::numeric_limits<float>::infinity()))
          reach.push_back(&b);
      if (reach.empty()) continue;
      for (int v = v0; v < v1; ++v)
        for (int u = u0; u < u1; ++u) {
          const size_t t = size_t(v) * size_t(columns_) + size_t(u);
          const uint32_t id = texelRecord_[t];
          if (id == 0) continue;
          const Cone texel{records_[id].position, options_.recordSpacing,
                           texelDirection(int64_t(t)), texelHalf};
          for (const Box3f* b : reach)
            if (texel.mayMeet(*b, hitDistance_[t])) {
              forget(t);
              ++forgotten;
              break;
            }
        }
    }
  return forgotten;
}

}  // namespace vistream
