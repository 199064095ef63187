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
// Runs and joints: a line's cover is cut into runs, the stretches between
// its gaps, each exact to the triangle corners it ends at. The end of a run
// (a triangle corner projected on its line's plane) that lies within
// `jointTolerance` of another line's plane, at a tangential coordinate
// within `jointTolerance` of one of that line's runs, is joined to it there
// (a building's corner; a wall ending on another): a chain of walls may
// turn from one to the other. Between the triangles of the two lines the
// crack is then at most 3 x `tolerance` + sqrt(2) x `jointTolerance` wide
// (each line's triangles off its plane, one cover's joining along it).
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
  double u0 = 0.0;         // tangential coordinate where bin 0 starts: the line's first corner
  double u1 = 0.0;         // its last corner, where the last bin ends
  uint32_t firstBin = 0, binCount = 0;
  uint32_t firstRun = 0, runCount = 0;            // in run(), by ua
  uint32_t firstTriangle = 0, triangleCount = 0;  // members, in triangles()
  float maxTop = 0.0f;                            // highest top of any bin
  // The point of the plane at tangential coordinate u (X/Z).
  glm::dvec2 at(double u) const { return c * n + u * t; }
};

// A stretch [ua, ub] of a line covered without a gap, and the covers of
// the parts of its first and last bins it holds ((0, -1): none).
struct WallRun {
  double ua = 0.0, ub = 0.0;
  glm::vec2 head{0.0f, -1.0f}, tail{0.0f, -1.0f};
};

// Run `run` of line `line`, at tangential coordinate u in it, is joined to
// the end of another line's run.
struct WallJoint {
  uint32_t line = 0, run = 0;
  double u = 0.0;
};

class WallOccluders {
 public:
  WallOccluders() = default;
  // Groups the non-degenerate triangles of `tris` that stand within
  // `tolerance` metres of a vertical plane and are taller than it, computes
  // each line's covered heights and joins run ends within `jointTolerance`
  // of another line. Every parameter positive and finite (VS_CHECK),
  // `jointTolerance` below 0.2 m.
  WallOccluders(const FlatTriangles& tris, double tolerance, double binSize, double jointTolerance);

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
  // The run of line k holding tangential coordinate u, if any.
  std::optional<uint32_t> runOf(size_t k, double u) const;
  const WallRun& run(uint32_t r) const { return runs_[r]; }
  // The runs joined to run r at its end: end 0 at ua, end 1 at ub.
  std::span<const WallJoint> joints(uint32_t r, int end) const {
    const size_t e = 2 * size_t(r) + size_t(end != 0);
    return {joints_.data() + jointStart_[e], jointStart_[e + 1] - jointStart_[e]};
  }
  double binSize() const { return binSize_; }
  double tolerance() const { return tolerance_; }
  double jointTolerance() const { return jointTolerance_; }

 private:
  void buildJoints();
  // The bin holding u from the right (its first) and from the left (its
  // last), clamped to the line's bins.
  uint32_t headBin(const WallLine& line, double u) const;
  uint32_t tailBin(const WallLine& line, double u) const;

  std::vector<WallLine> lines_;
  std::vector<uint32_t> members_;
  std::vector<glm::vec2> bins_;  // (base, top); top < base: not covered
  std::vector<WallRun> runs_;
  std::vector<uint32_t> jointStart_;  // CSR over run ends (2 r, 2 r + 1)
  std::vector<WallJoint> joints_;
  double binSize_ = 0.25, tolerance_ = 1e-3, jointTolerance_ = 5e-4;
};

}  // namespace vistream
