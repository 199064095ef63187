// The panoramic image cache (thesis section 4.4).
//
// A cylindrical map around the viewer stores traced far-field colours by
// direction: azimuth around the Y axis and slope (tangent of the elevation)
// up the cylinder, so a stored colour stays valid when the viewer turns.
// Every texel points to a confidence record holding the observer position it
// was traced from (Figure 4.6). Each frame:
//  1. the candidate pixels (not covered by polygons, not sky) count their
//     texels' records;
//  2. records are ranked by the distance from their position to the current
//     one, and the pixel budget goes to the farthest first; when a record
//     holds more pixels than the budget has left, only every n-th of them is
//     retraced, and the rest are picked up in the next frame (graceful
//     degradation);
//  3. texels never traced, and texels whose record lies farther than
//     `maxStale` away, are always retraced, budget or not: the cache never
//     shows a colour from far away (after a teleport, say);
//  4. beyond the thesis: texels on a colour edge (a 4-neighbour differs) are
//     always retraced too. A screen pixel maps to a texel up to half a texel
//     off its own direction, which the thesis names as the cache's aliasing;
//     inside a uniform patch that offset changes nothing, at an edge it shows
//     the wrong side. Retracing only the edge texels (after the view turned,
//     or when traced from another position) removes most of that error for a
//     few rays. Neighbours never traced do not count.
// A new record is opened whenever the observer has moved more than
// `recordSpacing` since the current one; records no texel points to are
// recycled, so their number stays below the number of texels.
//
// Geometry that changes (a streaming client's) invalidates only the texels it
// may change (invalidate()): each texel keeps the distance its ray travelled
// to its hit and the triangle it hit. A texel's ray left from within
// `recordSpacing` of its record's position, in a direction inside the texel's
// patch of azimuth and slope; new triangles can change it only if such a ray
// meets their bounds before its recorded hit, and removed triangles only if
// it hit one of them. Every other texel stays.
//
// Thread safety: none; one cache per viewer, used from one thread.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <span>
#include <vector>

#include "common/core/box.h"

namespace vistream {

struct PanoramicCacheOptions {
  float texelsPerPixel = 1.0f;  // angular resolution relative to a screen pixel at the image centre
                                // (coarser if the panorama would exceed 64 Mi texels)
  float maxSlope = 1.7320508f;  // rays steeper than tan(60 deg) up or down are not cached
  float recordSpacing = 0.01f;  // metres the observer moves before a new confidence record opens
  bool retraceEdges = true;     // texels whose 4 neighbours differ in colour are always retraced
};

struct CachePlanStats {
  size_t candidates = 0;           // pixels that asked
  size_t mustTrace = 0;            // never traced, outside the cached band, or too stale
  size_t budgeted = 0;             // retraced by the budget (oldest records first)
  size_t edges = 0;                // retraced because the texel lies on a colour edge
  size_t reused = 0;               // taken from the cache
  bool degraded = false;           // some stale-but-valid pixels were left for later frames
  float thresholdDistance = 0.0f;  // records farther than this were retraced
};

class PanoramicCache {
 public:
  // pixelAngle: the angle one screen pixel spans at the image centre (Camera::pixelAngle).
  PanoramicCache(float pixelAngle, const PanoramicCacheOptions& options = {});

  size_t texelCount() const { return colours_.size(); }
  glm::ivec2 dims() const { return {columns_, rows_}; }
  size_t liveRecords() const { return records_.size() - free_.size(); }

  // The texel a view direction maps to, or -1 if it lies outside the band.
  int64_t texelOf(const glm::vec3& dir) const;

  // Decides, for each candidate texel (one per candidate pixel, -1 for
  // outside the band), whether to retrace (trace[i] = 1) or reuse it.
  // `viewTurned`: the view direction changed since the last frame, so pixels
  // map to texels off their own direction (edge texels are then retraced;
  // without turning, only edge texels traced from elsewhere are).
  CachePlanStats plan(const glm::vec3& eye, std::span<const int64_t> texels, size_t budget,
                      float maxStale, std::vector<uint8_t>& trace, bool viewTurned = true);
  glm::u8vec3 colour(int64_t texel) const { return colours_[size_t(texel)]; }
  // Stores a traced colour under the current record (opened by plan()):
  // hitDistance (metres from the eye to the hit; infinity for a miss) and
  // the triangle hit (kNoTexelHit for none) decide what invalidate() keeps.
  static constexpr uint32_t kNoTexelHit = 0xffffffffu;
  // The texel shows an impostor's point (the far field composited with the
  // impostors, thesis chapter 5), stored with the point's distance: valid
  // while the same impostors are drawn (invalidate(..., forgetImpostors)).
  static constexpr uint32_t kImpostorTexelHit = 0xfffffffeu;
  void store(int64_t texel, glm::u8vec3 colour,
             float hitDistance = std::numeric_limits<float>::infinity(),
             uint32_t triangle = kNoTexelHit);
  void clear();

  // Forgets (as never traced) every texel the change of the geometry may
  // have changed: texels whose ray hit a triangle with removed[triangle] != 0,
  // and texels whose ray may meet one of the `added` boxes before its hit
  // (conservatively: a cone over the texel's directions from a ball of radius
  // recordSpacing around the record's position). `added` must hold every
  // added triangle (or impostor); smaller boxes keep more texels. With
  // `forgetImpostors`, every texel showing an impostor goes too (the
  // impostors drawn changed). Returns the texels forgotten.
  size_t invalidate(std::span<const Box3f> added, std::span<const uint8_t> removed,
                    bool forgetImpostors = false);
  // Whether a texel holds a traced colour (not forgotten, never traced).
  bool traced(int64_t texel) const { return texelRecord_[size_t(texel)] != 0; }
  // Metres from the eye to the texel's stored hit (infinity for a miss).
  float hitDistance(int64_t texel) const { return hitDistance_[size_t(texel)]; }
  // Whether the texel was stored as an impostor's point (kImpostorTexelHit).
  bool showsImpostor(int64_t texel) const {
    return hitTriangle_[size_t(texel)] == kImpostorTexelHit;
  }
  // The unit direction through a texel's centre.
  glm::vec3 texelDirection(int64_t texel) const;

 private:
  struct Record {
    glm::vec3 position{0.0f};
    uint32_t refs = 0;   // texels pointing here
    uint32_t count = 0;  // candidate pixels this frame
    float distance = 0.0f;
  };
  uint32_t openRecord(const glm::vec3& eye);
  void release(uint32_t r);
  bool onEdge(int64_t texel) const;
  void forget(size_t texel);
  static constexpr int kTile = 16;  // invalidate() works in tiles of kTile x kTile texels
  size_t tileOf(int64_t texel) const {
    return size_t(texel / columns_ / kTile) * size_t(tileColumns_) +
           size_t(texel % columns_ / kTile);
  }

  int columns_ = 0, rows_ = 0;
  float maxSlope_ = 1.0f;
  PanoramicCacheOptions options_;
  std::vector<glm::u8vec3> colours_;
  std::vector<uint32_t> texelRecord_;  // 0: never traced
  std::vector<float> hitDistance_;     // per texel: metres to the hit, infinity for a miss
  std::vector<uint32_t> hitTriangle_;  // per texel: the triangle hit, kNoTexelHit for none
  int tileColumns_ = 0;
  std::vector<uint32_t> tileTraced_;  // per tile: texels traced
  std::vector<Record> records_;       // records_[0] is "never traced"
  std::vector<uint32_t> free_;
  uint32_t current_ = 0;
  std::vector<uint32_t> touched_, partialStep_, partialSeen_;
};

}  // namespace vistream
