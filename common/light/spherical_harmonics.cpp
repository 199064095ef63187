#include "common/light/spherical_harmonics.h"

#include <array>
#include <cmath>
#include <cstdlib>
#include <numbers>

#include "common/core/check.h"

namespace vistream {
namespace {

// K_l^m for l <= 4, with the sqrt(2) of m != 0 folded in.
struct Normalization {
  std::array<std::array<double, kMaxShOrder + 1>, kMaxShOrder + 1> k{};
  Normalization() {
    auto factorial = [](int n) {
      double f = 1.0;
      for (int i = 2; i <= n; ++i) f *= i;
      return f;
    };
    for (int l = 0; l <= kMaxShOrder; ++l)
      for (int m = 0; m <= l; ++m)
        k[size_t(l)][size_t(m)] = std::sqrt((2.0 * l + 1.0) / (4.0 * std::numbers::pi) *
                                            factorial(l - m) / factorial(l + m)) *
                                  (m == 0 ? 1.0 : std::sqrt(2.0));
  }
};
const Normalization kNormalization;

}  // namespace

void shEvaluate(const glm::vec3& d, int orders, float* out) {
  VS_CHECK(orders >= 1 && orders <= kMaxShOrder + 1);
  const double x = d.x, y = d.y, z = d.z;
  // Q_l^m(z) = P_l^m(z) / sin^m(theta), by the standard recurrences in l;
  // sin^m(theta) cos(m phi) and sin^m(theta) sin(m phi) are the real and
  // imaginary parts of (x + i y)^m.
  double re = 1.0, im = 0.0;  // (x + i y)^m
  double qmm = 1.0;           // Q_m^m = (2m - 1)!!
  for (int m = 0; m < orders; ++m) {
    if (m > 0) {
      const double r = re * x - im * y;
      im = re * y + im * x;
      re = r;
      qmm *= 2.0 * m - 1.0;
    }
    double q2 = 0.0, q1 = qmm;  // Q_{l-2}^m, Q_{l-1}^m
    for (int l = m; l < orders; ++l) {
      double q;
      if (l == m)
        q = qmm;
      else if (l == m + 1)
        q = z * (2.0 * m + 1.0) * qmm;
      else
        q = (z * (2.0 * l - 1.0) * q1 - (l + m - 1.0) * q2) / double(l - m);
      if (l > m) {
        q2 = q1;
        q1 = q;
      }
      const double k = kNormalization.k[size_t(l)][size_t(m)] * q;
      if (m == 0) {
        out[l * (l + 1)] = float(k);
      } else {
        out[l * (l + 1) + m] = float(k * re);
        out[l * (l + 1) - m] = float(k * im);
      }
    }
  }
}

double clampedCosineZonal(int l) {
  VS_CHECK(l >= 0 && l <= kMaxShOrder);
  // 2 pi K_l^0 * integral_0^1 P_l(t) t dt; the integrals for l = 0..4.
  constexpr double integral[5] = {1.0 / 2.0, 1.0 / 3.0, 1.0 / 8.0, 0.0, -1.0 / 48.0};
  return 2.0 * std::numbers::pi * std::sqrt((2.0 * l + 1.0) / (4.0 * std::numbers::pi)) *
         integral[l];
}

namespace {

// Ivanic and Ruedenberg's P, U, V, W for band l, from band 1 (r1) and band
// l - 1 (prev), both indexed (m, n) from their lowest order.
struct BandRecurrence {
  int l;
  const std::array<float, 81>& r1;
  const std::array<float, 81>& prev;

  double r(int i, int j) const { return r1[size_t((i + 1) * 3 + (j + 1))]; }
  double d(int a, int b) const {
    const int k = l - 1;
    return prev[size_t((a + k) * (2 * k + 1) + (b + k))];
  }
  double p(int i, int a, int b) const {
    if (b == l) return r(i, 1) * d(a, l - 1) - r(i, -1) * d(a, -l + 1);
    if (b == -l) return r(i, 1) * d(a, -l + 1) + r(i, -1) * d(a, l - 1);
    return r(i, 0) * d(a, b);
  }
  double u(int m, int n) const { return p(0, m, n); }
  double v(int m, int n) const {
    if (m == 0) return p(1, 1, n) + p(-1, -1, n);
    if (m > 0) {
      const bool one = m == 1;
      return p(1, m - 1, n) * std::sqrt(one ? 2.0 : 1.0) - (one ? 0.0 : p(-1, -m + 1, n));
    }
    const bool one = m == -1;
    return (one ? 0.0 : p(1, m + 1, n)) + p(-1, -m - 1, n) * std::sqrt(one ? 2.0 : 1.0);
  }
  double w(int m, int n) const {
    if (m == 0) return 0.0;
    if (m > 0) return p(1, m + 1, n) + p(-1, -m - 1, n);
    return p(1, m - 1, n) - p(-1, -m + 1, n);
  }
  double entry(int m, int n) const {
    const int am = std::abs(m);
    const double delta = m == 0 ? 1.0 : 0.0;
    const double denom =
        std::abs(n) == l ? double(2 * l) * double(2 * l - 1) : double(l + n) * double(l - n);
    const double cu = std::sqrt(double(l + m) * double(l - m) / denom);
    const double cv = 0.5 * std::sqrt((1.0 + delta) * double(l + am - 1) * double(l + am) / denom) *
                      (1.0 - 2.0 * delta);
    const double cw = -0.5 * std::sqrt(double(l - am - 1) * double(l - am) / denom) * (1.0 - delta);
    double e = 0.0;
    if (cu != 0.0) e += cu * u(m, n);
    if (cv != 0.0) e += cv * v(m, n);
    if (cw != 0.0) e += cw * w(m, n);
    return e;
  }
};

}  // namespace

ShRotation::ShRotation(const glm::mat3& r, int orders) : orders_(orders) {
  VS_CHECK(orders >= 1 && orders <= kMaxShOrder + 1);
  bands_[0][0] = 1.0f;
  if (orders < 2) return;
  // Band 1: Y_1^{-1,0,1} are c (y, z, x), so D_1(m, n) = r(axis m, axis n).
  const int axis[3] = {1, 2, 0};
  for (int m = -1; m <= 1; ++m)
    for (int n = -1; n <= 1; ++n)
      bands_[1][size_t((m + 1) * 3 + (n + 1))] = r[axis[n + 1]][axis[m + 1]];  // r[col][row]
  for (int l = 2; l < orders; ++l) {
    const BandRecurrence rec{l, bands_[1], bands_[size_t(l - 1)]};
    for (int m = -l; m <= l; ++m)
      for (int n = -l; n <= l; ++n)
        bands_[size_t(l)][size_t((m + l) * (2 * l + 1) + (n + l))] = float(rec.entry(m, n));
  }
}

void ShRotation::apply(const float* in, float* out) const {
  for (int l = 0; l < orders_; ++l) {
    const int base = l * l, size = 2 * l + 1;
    const float* block = bands_[size_t(l)].data();
    for (int m = 0; m < size; ++m) {
      float sum = 0.0f;
      for (int n = 0; n < size; ++n) sum += block[m * size + n] * in[base + n];
      out[base + m] = sum;
    }
  }
}

}  // namespace vistream
