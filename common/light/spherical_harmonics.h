// Real spherical harmonics of orders 0..4 (up to 25 terms), as the
// environment light (9 terms) and the avatars' radiance transfer (25 terms,
// Kautz et al. 2004) use them.
//
// Convention: index l (l + 1) + m for order l and -l <= m <= l; Y_l^m is
// sqrt(2) K_l^|m| P_l^|m|(z) times cos(m phi) for m > 0 and sin(|m| phi) for
// m < 0, K_l^0 P_l^0(z) for m = 0, with K_l^m = sqrt((2l + 1) / (4 pi) *
// (l - m)! / (l + m)!), polar axis z and no Condon-Shortley phase: Y_1^{-1},
// Y_1^0, Y_1^1 are 0.4886 (y, z, x). The functions are orthonormal over the
// sphere.
#pragma once

#include <array>
#include <glm/glm.hpp>

namespace vistream {

inline constexpr int kMaxShOrder = 4;  // orders 0..4: 25 terms

constexpr int shTerms(int orders) {  // orders 1..5 -> 1, 4, 9, 16, 25
  return orders * orders;
}

// The first shTerms(orders) basis functions (orders 1..5) at unit direction
// d, written to out[0 .. terms).
void shEvaluate(const glm::vec3& d, int orders, float* out);

// The clamped cosine max(0, n . s) about +z, projected: only m = 0 terms are
// non-zero, and their coefficients are returned per order l (0..4). The
// convolution weights of Ramamoorthi and Hanrahan are these times
// sqrt(4 pi / (2l + 1)).
double clampedCosineZonal(int l);

// The rotation of SH coefficient vectors that goes with a rotation r of
// directions: for a function f with coefficients c, the function f(r^T w)
// (f turned by r) has coefficients apply(c); equivalently Y(r s) = D Y(s)
// for the basis vector Y. Band-diagonal; band 1 is r itself with its rows
// and columns in (y, z, x) order, higher bands follow by the recurrences of
// Ivanic and Ruedenberg (1996, with their 1998 corrections).
class ShRotation {
 public:
  // r: a rotation matrix (orthonormal, determinant 1; glm's column-major),
  // orders 1..5.
  ShRotation(const glm::mat3& r, int orders);
  int orders() const { return orders_; }
  // out = D in, over shTerms(orders) coefficients (in and out distinct).
  void apply(const float* in, float* out) const;
  // Entry (m, n) of band l's (2l + 1)^2 block, m and n in -l..l.
  float at(int l, int m, int n) const {
    return bands_[size_t(l)][size_t((m + l) * (2 * l + 1) + (n + l))];
  }

 private:
  int orders_;
  std::array<std::array<float, 81>, kMaxShOrder + 1> bands_{};
};

}  // namespace vistream
