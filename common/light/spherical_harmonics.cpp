#include "common/light/spherical_harmonics.h"

#include <array>
#include <cmath>

#include "common/core/check.h"

namespace vistream {
namespace {

constexpr double kPi = 3.14159265358979323846;

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
        k[size_t(l)][size_t(m)] =
            std::sqrt((2.0 * l + 1.0) / (4.0 * kPi) * factorial(l - m) / factorial(l + m)) *
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
  return 2.0 * kPi * std::sqrt((2.0 * l + 1.0) / (4.0 * kPi)) * integral[l];
}

}  // namespace vistream
