// Watertight ray/triangle intersection (Woop, Benthin and Wald, "Watertight
// Ray/Triangle Intersection", JCGT 2013), evaluated in double precision.
//
// Closed triangles: a ray through an edge or a vertex hits every triangle
// that shares it, so a mesh without gaps lets nothing through. Degenerate
// triangles (zero determinant after the shear) are never hit. Shared by the
// brute-force oracle and the kD-tree back end so that both decide seams the
// same way.
#pragma once

#include <cmath>
#include <glm/glm.hpp>
#include <optional>

namespace vistream {

struct TriangleHit {
  double t;
  double u, v;  // barycentrics of b and c
};

inline std::optional<TriangleHit> intersectWatertight(const glm::dvec3& org, const glm::dvec3& dir,
                                                      double tnear, double tfar,
                                                      const glm::dvec3& a, const glm::dvec3& b,
                                                      const glm::dvec3& c) {
  // Permute axes so that the ray's dominant direction is z.
  const glm::dvec3 ad = glm::abs(dir);
  int kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
  if (ad[kz] == 0.0) return std::nullopt;
  int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
  if (dir[kz] < 0.0) std::swap(kx, ky);  // keep winding

  const double sx = dir[kx] / dir[kz], sy = dir[ky] / dir[kz], sz = 1.0 / dir[kz];
  const glm::dvec3 A = a - org, B = b - org, C = c - org;
  const double ax = A[kx] - sx * A[kz], ay = A[ky] - sy * A[kz];
  const double bx = B[kx] - sx * B[kz], by = B[ky] - sy * B[kz];
  const double cx = C[kx] - sx * C[kz], cy = C[ky] - sy * C[kz];

  const double U = cx * by - cy * bx;
  const double V = ax * cy - ay * cx;
  const double W = bx * ay - by * ax;
  if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return std::nullopt;
  const double det = U + V + W;
  if (det == 0.0) return std::nullopt;

  const double az = sz * A[kz], bz = sz * B[kz], cz = sz * C[kz];
  const double T = U * az + V * bz + W * cz;
  const double t = T / det;
  if (!(t >= tnear && t <= tfar)) return std::nullopt;
  return TriangleHit{t, V / det, W / det};
}

}  // namespace vistream
