// Axis-aligned boxes. Closed: a point on the boundary is inside.
#pragma once

#include <algorithm>
#include <glm/glm.hpp>
#include <limits>

namespace vistream {

template <typename T>
struct BasicBox3 {
  using Vec = glm::vec<3, T>;
  Vec lo{std::numeric_limits<T>::max()};
  Vec hi{std::numeric_limits<T>::lowest()};

  BasicBox3() = default;
  BasicBox3(const Vec& a, const Vec& b) : lo(glm::min(a, b)), hi(glm::max(a, b)) {}

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void extend(const Vec& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  void extend(const BasicBox3& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  Vec extent() const { return empty() ? Vec(0) : hi - lo; }
  Vec center() const { return (lo + hi) * T(0.5); }
  // Corner k in 0..7: bit 0 picks hi.x over lo.x, bit 1 hi.y, bit 2 hi.z.
  Vec corner(int k) const {
    return {k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z};
  }
  T surfaceArea() const {
    const Vec d = extent();
    return T(2) * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
  int longestAxis() const {
    const Vec d = extent();
    return d.x >= d.y && d.x >= d.z ? 0 : (d.y >= d.z ? 1 : 2);
  }
  bool contains(const Vec& p) const {
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
  }
  bool overlaps(const BasicBox3& b) const {
    return lo.x <= b.hi.x && b.lo.x <= hi.x && lo.y <= b.hi.y && b.lo.y <= hi.y && lo.z <= b.hi.z &&
           b.lo.z <= hi.z;
  }
  // Euclidean distance to box b: the shortest segment between them, 0 when
  // they overlap or touch.
  T distanceTo(const BasicBox3& b) const {
    return glm::length(glm::max(Vec(0), glm::max(lo - b.hi, b.lo - hi)));
  }
  BasicBox3 intersection(const BasicBox3& b) const {
    BasicBox3 r;
    r.lo = glm::max(lo, b.lo);
    r.hi = glm::min(hi, b.hi);
    return r;
  }
};

using Box3f = BasicBox3<float>;
using Box3d = BasicBox3<double>;

}  // namespace vistream
