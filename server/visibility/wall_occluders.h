// Vertical walls of the static geometry, as occluders for the occlusion
// horizons (horizon_fusion.cpp, proof step 7): the walls of open meshes (row
// blocks whose walls leave slits, facades without a back) and of closed ones
// alike, wherever the triangles stand upright.
//
// A wall line is a group of near-vertical triangles whose corners all lie
// within `tolerance` of one vertical plane (a line in X/Z). Along the line,
// the tangential coordinate u is cut into bins of `binSize` metres; each bin
// keeps a height interval [base, top] that the union of the group's
// triangles covers at every u of the bin (cracks between the triangles
// narrower than `tolerance` taken as closed, as the solids' welding does).
// cover(line, ua, ub) gives the interval covered at every u of [ua, ub]: a
// line of sight crossing the line's plane at a tangential position in
// [ua, ub] and a height in that interval meets a triangle there.
//
// Frames and units: the scene's local frame, metres, Y up. The normal n of a
// line is horizontal, of unit length, with n.x > 0 or (n.x == 0, n.y > 0)
// (n.y standing for Z); the tangent is t = (-n.y, n.x); a point p lies on
// the line when n . (p.x, p.z) = c, and its tangential coordinate is
// t . (p.x, p.z).
//
// Thread safety: immutable after construction; const methods may run
// concurrently.
#pragma once

#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "common/scene/scene.h"

namespace vistream {

// The two corners of triangle t whose X/Z projections lie farthest apart
// (in their order around the triangle; the first such edge on ties): for an
// upright triangle, the ends of the segment its projection is.
std::pair<glm::dvec2, glm::dvec2> farthestXzCorners(const FlatTriangles& tris, size_t t);

struct WallLine {
  glm::dvec2 n{1.0, 0.0};  // unit horizontal normal (x, z)
  glm::dvec2 t{0.0, 1.0};  // tangent (-n.y, n.x)
  double c = 0.0;          // n . (x, z) on the line
  double u0 = 0.0;         // tangential coordinate where bin 0 starts
  uint32_t firstBin = 0, binCount = 0;
  uint32_t firstTriangle = 0, triangleCount = 0;  // members, in triangles()
  float maxTop = 0.0f;                            // highest top of any bin
};

class WallOccluders {
 public:
  WallOccluders() = default;
  // Groups the non-degenerate triangles of `tris` that stand within
  // `tolerance` metres of a vertical plane and are taller than it, and
  // computes each line's covered heights. Both parameters positive and
  // finite (VS_CHECK).
  WallOccluders(const FlatTriangles& tris, double tolerance, double binSize);

  size_t size() const { return lines_.size(); }
  const WallLine& line(size_t k) const { return lines_[k]; }
  // Triangle indices (into the FlatTriangles given) of line k.
  std::span<const uint32_t> triangles(size_t k) const {
    return {members_.data() + lines_[k].firstTriangle, lines_[k].triangleCount};
  }
  // The heights (base, top) that line k's triangles cover at every
  // tangential coordinate in [ua, ub]; nothing when some u there is not
  // covered (off the line's bins, or a bin without cover).
  std::optional<glm::dvec2> cover(size_t k, double ua, double ub) const;
  double binSize() const { return binSize_; }
  double tolerance() const { return tolerance_; }

 private:
  std::vector<WallLine> lines_;
  std::vector<uint32_t> members_;
  std::vector<glm::vec2> bins_;  // (base, top); top < base: not covered
  double binSize_ = 0.25, tolerance_ = 1e-3;
};

}  // namespace vistream
