#include "common/avatar/self_shadow.h"

#include <meshoptimizer.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <numbers>

#include "common/core/check.h"
#include "common/core/random.h"
#include "common/core/tangent_frame.h"
#include "common/light/spherical_harmonics.h"
#include "common/raycast/ray_query.h"

namespace vistream {
namespace {

float meshSize(const std::vector<glm::vec3>& positions) {
  glm::vec3 lo(INFINITY), hi(-INFINITY);
  for (const glm::vec3& p : positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  return positions.empty() ? 1.0f : glm::length(hi - lo);
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Whether a group's sphere lies wholly below the tangent plane of the vertex
// at p with unit normal n. The margin keeps every triangle a per-triangle
// test would draw: a culled group's vertices are all below the plane by more
// than rounding, in any frame.
bool sphereBelow(const glm::vec4& sphere, const glm::vec3& p, const glm::vec3& n) {
  const glm::vec3 d = glm::vec3(sphere) - p;
  const float margin = 1e-4f * (glm::length(d) + sphere.w);
  return glm::dot(d, n) + sphere.w < -margin;  // false for an infinite radius or NaN
}

// culled[g] for every group, for a vertex whose blockers are every triangle.
void cullGroups(const glm::vec3& p, const glm::vec3& normal, const std::vector<glm::vec4>& spheres,
                std::vector<uint8_t>& culled, uint64_t& count) {
  const glm::vec3 n = glm::normalize(normal);
  culled.resize(spheres.size());
  for (size_t g = 0; g < spheres.size(); ++g) {
    culled[g] = sphereBelow(spheres[g], p, n);
    count += culled[g];
  }
}

// The same, tested lazily for the groups a vertex's blocker list meets (a
// PVS lists a few triangles of a few groups): stamp[g] == generation marks
// group g as tested for the current vertex, with its answer in culled[g].
struct LazyCulling {
  std::vector<uint32_t> stamp;
  std::vector<uint8_t> culled;
  uint32_t generation = 0;

  void startVertex(size_t groups) {
    if (stamp.size() != groups || ++generation == 0) {
      stamp.assign(groups, 0);
      culled.assign(groups, 0);
      generation = 1;
    }
  }
  bool isCulled(uint32_t g, const std::vector<glm::vec4>& spheres, const glm::vec3& p,
                const glm::vec3& n, uint64_t& count) {
    if (stamp[g] != generation) {
      stamp[g] = generation;
      culled[g] = sphereBelow(spheres[g], p, n);
      count += culled[g];
    }
    return culled[g];
  }
};

}  // namespace

TriangleGroups TriangleGroups::build(const std::vector<glm::uvec3>& triangles,
                                     const std::vector<glm::vec3>& restPositions) {
  TriangleGroups g;
  g.groupOf.assign(triangles.size(), 0);
  if (triangles.empty()) return g;
  constexpr size_t kMaxVertices = 64;
  std::vector<uint32_t> indices;
  indices.reserve(3 * triangles.size());
  for (const glm::uvec3& t : triangles) {
    for (int k = 0; k < 3; ++k) VS_CHECK_LT(t[k], restPositions.size());
    indices.insert(indices.end(), {t.x, t.y, t.z});
  }
  const size_t bound = meshopt_buildMeshletsBound(indices.size(), kMaxVertices, kMaxTriangles);
  std::vector<meshopt_Meshlet> meshlets(bound);
  std::vector<unsigned int> meshletVertices(bound * kMaxVertices);
  std::vector<unsigned char> meshletTriangles(bound * kMaxTriangles * 3);
  meshlets.resize(meshopt_buildMeshlets(meshlets.data(), meshletVertices.data(),
                                        meshletTriangles.data(), indices.data(), indices.size(),
                                        &restPositions[0].x, restPositions.size(),
                                        sizeof(glm::vec3), kMaxVertices, kMaxTriangles, 0.0f));
  // Meshlets name their triangles by corners: find each one's index by its
  // sorted corners (repeated triangles take their indices in turn).
  std::map<std::array<uint32_t, 3>, std::vector<uint32_t>> byCorners;
  auto key = [](uint32_t a, uint32_t b, uint32_t c) {
    std::array<uint32_t, 3> k{a, b, c};
    std::sort(k.begin(), k.end());
    return k;
  };
  for (uint32_t t = uint32_t(triangles.size()); t-- > 0;)
    byCorners[key(triangles[t].x, triangles[t].y, triangles[t].z)].push_back(t);
  std::vector<uint8_t> placed(triangles.size(), 0);
  for (const meshopt_Meshlet& m : meshlets) {
    const uint32_t group = uint32_t(g.size());
    for (size_t k = 0; k < m.triangle_count; ++k) {
      const unsigned char* c = &meshletTriangles[m.triangle_offset + 3 * k];
      const unsigned int* v = &meshletVertices[m.vertex_offset];
      auto it = byCorners.find(key(v[c[0]], v[c[1]], v[c[2]]));
      if (it == byCorners.end() || it->second.empty()) continue;
      const uint32_t t = it->second.back();
      it->second.pop_back();
      placed[t] = 1;
      g.groupOf[t] = group;
      g.members.push_back(t);
    }
    g.vertices.insert(g.vertices.end(), meshletVertices.begin() + m.vertex_offset,
                      meshletVertices.begin() + m.vertex_offset + m.vertex_count);
    g.vertexStart.push_back(uint32_t(g.vertices.size()));
    g.triangleStart.push_back(uint32_t(g.members.size()));
    g.neverCulled.push_back(0);
  }
  // What the meshlets left out: one group that is never culled.
  const uint32_t rest = uint32_t(g.size());
  bool any = false;
  for (uint32_t t = 0; t < triangles.size(); ++t)
    if (!placed[t]) {
      any = true;
      g.groupOf[t] = rest;
      g.members.push_back(t);
    }
  if (any) {
    g.vertexStart.push_back(uint32_t(g.vertices.size()));
    g.triangleStart.push_back(uint32_t(g.members.size()));
    g.neverCulled.push_back(1);
  }
  return g;
}

void TriangleGroups::spheres(const std::vector<glm::vec3>& positions,
                             std::vector<glm::vec4>& out) const {
  out.resize(size());
  for (size_t g = 0; g < size(); ++g) {
    if (neverCulled[g] || vertexStart[g] == vertexStart[g + 1]) {
      out[g] = glm::vec4(0.0f, 0.0f, 0.0f, INFINITY);
      continue;
    }
    glm::vec3 lo(INFINITY), hi(-INFINITY);
    for (uint32_t k = vertexStart[g]; k < vertexStart[g + 1]; ++k) {
      lo = glm::min(lo, positions[vertices[k]]);
      hi = glm::max(hi, positions[vertices[k]]);
    }
    const glm::vec3 centre = 0.5f * (lo + hi);
    float r2 = 0.0f;
    for (uint32_t k = vertexStart[g]; k < vertexStart[g + 1]; ++k) {
      const glm::vec3 d = positions[vertices[k]] - centre;
      r2 = std::max(r2, glm::dot(d, d));
    }
    out[g] = glm::vec4(centre, std::sqrt(r2) * (1.0f + 1e-6f));
  }
}

SelfShadowing::SelfShadowing(const SelfShadowOptions& options)
    : options_(options),
      table_(options.planeTable > 0
                 ? std::make_unique<PlaneMaskTable>(options.maskSide, options.planeTable)
                 : nullptr),
      integrator_(options.maskSide, options.transfer) {}

template <class ForEachBlocker>
void SelfShadowing::run(const std::vector<glm::vec3>& positions,
                        const std::vector<glm::vec3>& normals, std::vector<float>& out,
                        const ShadeExtras& extras, size_t eager,
                        ForEachBlocker&& forEachBlocker) const {
  VS_CHECK_EQ(positions.size(), normals.size());
  const std::vector<uint8_t>* only = extras.only;
  const size_t words = size_t(maskWords());
  const int terms = integrator_.terms();
  if (only) {
    // The other vertices keep what they hold (zeros where the vectors grow).
    VS_CHECK_EQ(only->size(), positions.size());
    out.resize(positions.size() * size_t(terms), 0.0f);
    if (extras.masks) extras.masks->resize(positions.size() * words, 0);
  } else {
    out.assign(positions.size() * size_t(terms), 0.0f);
    if (extras.masks) extras.masks->assign(positions.size() * words, 0);
  }
  struct Local {
    VisibilityMask mask;
    SelfShadowStats stats;
    BlockerBatch batch;            // a vertex's blockers, to look up and draw
    std::vector<glm::vec3> eager;  // vertices [0, eager) in the vertex's frame
  };
  tbb::enumerable_thread_specific<Local> locals([&] {
    return Local{VisibilityMask(options_.maskSide), {}, {}, {}};
  });
  VS_CHECK_LE(eager, positions.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, positions.size(), 16), [&](const auto& range) {
    Local& local = locals.local();
    for (size_t v = range.begin(); v != range.end(); ++v) {
      if (only && !(*only)[v]) continue;  // left as it was
      ++local.stats.vertices;
      const auto start = std::chrono::steady_clock::now();
      const glm::vec3 p = positions[v];
      const TangentFrame frame = TangentFrame::around(normals[v]);
      local.mask.clear();
      local.batch.clear();
      // Vertices [0, eager) in the tangent frame, once: their triangles
      // then cost three loads instead of three transforms.
      local.eager.resize(eager);
      for (size_t k = 0; k < eager; ++k) local.eager[k] = frame.toLocal(positions[k] - p);
      auto draw = [&](const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
        ++local.stats.blockerTests;
        if (!(std::max({a.z, b.z, c.z}) > 0.0f)) return;
        if (!table_) {
          local.stats.rasterized += rasterizeBlocker(a, b, c, nullptr, local.mask);
          return;
        }
        local.stats.rasterized += local.batch.add(a, b, c);  // drawn together below
      };
      auto block = [&](const glm::uvec3& t) {
        draw(frame.toLocal(positions[t.x] - p), frame.toLocal(positions[t.y] - p),
             frame.toLocal(positions[t.z] - p));
      };
      auto blockEager = [&](const glm::uvec3& t) {
        draw(local.eager[t.x], local.eager[t.y], local.eager[t.z]);
      };
      forEachBlocker(v, local.stats, block, blockEager);
      if (table_) local.batch.draw(*table_, local.mask);
      const auto integrated = std::chrono::steady_clock::now();
      local.stats.rasterSeconds += std::chrono::duration<double>(integrated - start).count();
      integrator_.diffuse(local.mask, frame, out.data() + v * size_t(terms));
      if (extras.masks) std::copy_n(local.mask.data(), words, extras.masks->data() + v * words);
      local.stats.integrateSeconds += seconds(integrated);
    }
  });
  if (SelfShadowStats* stats = extras.stats) {
    *stats = SelfShadowStats{};
    for (const Local& l : locals) {
      stats->vertices += l.stats.vertices;
      stats->blockerTests += l.stats.blockerTests;
      stats->groupsCulled += l.stats.groupsCulled;
      stats->rasterized += l.stats.rasterized;
      stats->rasterSeconds += l.stats.rasterSeconds;
      stats->integrateSeconds += l.stats.integrateSeconds;
    }
  }
}

void SelfShadowing::diffuse(const std::vector<glm::vec3>& positions,
                            const std::vector<glm::vec3>& normals,
                            const std::vector<glm::uvec3>& triangles, std::vector<float>& out,
                            const ShadeExtras& extras) const {
  const ShadowHierarchy* hierarchy = extras.hierarchy;
  const TriangleGroups* groups = extras.groups;
  std::vector<glm::vec4> spheres;
  const bool cull = options_.cullGroups && !hierarchy && groups && !groups->empty();
  if (cull) {
    VS_CHECK_EQ(groups->groupOf.size(), triangles.size());
    groups->spheres(positions, spheres);
  }
  // Transform every vertex once per receiving vertex where triangles outnumber
  // vertices (a closed mesh has about twice as many); with a hierarchy, the
  // coarse mesh's vertices (the first ones). With group culling this may
  // transform vertices only culled groups use (measured on the Fox: no
  // slower than transforming the corners of the surviving triangles).
  size_t eager = 0;
  if (hierarchy) {
    for (const glm::uvec3& t : hierarchy->coarse)
      eager = std::max<size_t>(eager, size_t(std::max({t.x, t.y, t.z})) + 1);
  } else if (positions.size() <= triangles.size()) {
    eager = positions.size();
  }
  run(positions, normals, out, extras, eager,
      [&](size_t v, SelfShadowStats& s, auto&& block, auto&& blockEager) {
        if (cull) {
          thread_local std::vector<uint8_t> culled;
          cullGroups(positions[v], normals[v], spheres, culled, s.groupsCulled);
          for (size_t g = 0; g < groups->size(); ++g)
            if (!culled[g])
              for (uint32_t k = groups->triangleStart[g]; k < groups->triangleStart[g + 1]; ++k) {
                const glm::uvec3& t = triangles[groups->members[k]];
                eager ? blockEager(t) : block(t);
              }
          return;
        }
        if (!hierarchy) {
          for (const glm::uvec3& t : triangles) eager ? blockEager(t) : block(t);
          return;
        }
        const ShadowHierarchy& h = *hierarchy;
        for (uint32_t k = h.ringStart[v]; k < h.ringStart[v + 1]; ++k)
          block(triangles[h.ringTriangles[k]]);
        const uint32_t* skip = h.skipTriangles.data() + h.skipStart[v];
        const uint32_t* skipEnd = h.skipTriangles.data() + h.skipStart[v + 1];
        for (uint32_t c = 0; c < h.coarse.size(); ++c) {
          if (skip != skipEnd && *skip == c) {  // sorted: one pass
            ++skip;
            continue;
          }
          blockEager(h.coarse[c]);
        }
      });
}

void SelfShadowing::diffuse(const std::vector<glm::vec3>& positions,
                            const std::vector<glm::vec3>& normals, const VertexBlockers& blockers,
                            std::vector<float>& out, const ShadeExtras& extras) const {
  VS_CHECK_EQ(blockers.vertices(), positions.size());
  std::vector<glm::vec4> spheres;
  const TriangleGroups& groups = blockers.groups;
  const bool cull = options_.cullGroups && !groups.empty();
  if (cull) {
    VS_CHECK_EQ(groups.groupOf.size(), blockers.triangles.size());
    groups.spheres(positions, spheres);
  }
  run(positions, normals, out, extras, 0,
      [&](size_t v, SelfShadowStats& s, auto&& block, auto&& /*blockEager: unused*/) {
        if (!cull) {
          for (uint32_t k = blockers.start[v]; k < blockers.start[v + 1]; ++k)
            block(blockers.triangles[blockers.list[k]]);
          return;
        }
        thread_local LazyCulling lazy;
        lazy.startVertex(groups.size());
        const glm::vec3 p = positions[v], n = glm::normalize(normals[v]);
        for (uint32_t k = blockers.start[v]; k < blockers.start[v + 1]; ++k) {
          const uint32_t t = blockers.list[k];
          if (!lazy.isCulled(groups.groupOf[t], spheres, p, n, s.groupsCulled))
            block(blockers.triangles[t]);
        }
      });
}

double VertexBlockers::meanPerVertex() const {
  return vertices() ? double(list.size()) / double(vertices()) : 0.0;
}

VertexBlockers VertexBlockers::everyTriangle(const std::vector<glm::uvec3>& triangles,
                                             size_t vertices) {
  VertexBlockers b;
  b.triangles = triangles;
  b.list.reserve(vertices * triangles.size());
  for (size_t v = 0; v < vertices; ++v) {
    for (uint32_t t = 0; t < triangles.size(); ++t) b.list.push_back(t);
    b.start.push_back(uint32_t(b.list.size()));
  }
  return b;
}

VertexBlockers VertexBlockers::of(const ShadowHierarchy& h, const std::vector<glm::uvec3>& fine) {
  VertexBlockers b;
  b.triangles = fine;
  b.triangles.insert(b.triangles.end(), h.coarse.begin(), h.coarse.end());
  const uint32_t coarseFirst = uint32_t(fine.size());
  for (size_t v = 0; v + 1 < h.ringStart.size(); ++v) {
    b.list.insert(b.list.end(), h.ringTriangles.begin() + h.ringStart[v],
                  h.ringTriangles.begin() + h.ringStart[v + 1]);
    const uint32_t* skip = h.skipTriangles.data() + h.skipStart[v];
    const uint32_t* skipEnd = h.skipTriangles.data() + h.skipStart[v + 1];
    for (uint32_t c = 0; c < h.coarse.size(); ++c) {
      if (skip != skipEnd && *skip == c) {
        ++skip;
        continue;
      }
      b.list.push_back(coarseFirst + c);
    }
    b.start.push_back(uint32_t(b.list.size()));
  }
  return b;
}

VertexBlockers potentiallyVisibleBlockers(const VertexBlockers& candidates,
                                          const std::vector<PosedMesh>& poses,
                                          const SelfShadowOptions& options) {
  const size_t vertices = candidates.vertices();
  for (const PosedMesh& p : poses) {
    VS_CHECK_EQ(p.positions.size(), vertices);
    VS_CHECK_EQ(p.normals.size(), vertices);
  }
  const std::unique_ptr<PlaneMaskTable> table =
      options.planeTable > 0
          ? std::make_unique<PlaneMaskTable>(options.maskSide, options.planeTable)
          : nullptr;
  std::vector<std::vector<uint32_t>> kept(vertices);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, vertices, 8), [&](const auto& range) {
    VisibilityMask mask(options.maskSide);
    std::vector<uint64_t> before(size_t(mask.words()));
    std::vector<std::pair<float, uint32_t>> order;  // (distance^2, slot)
    std::vector<glm::vec3> local;                   // 3 per slot
    std::vector<uint8_t> keep;
    for (size_t v = range.begin(); v != range.end(); ++v) {
      const uint32_t first = candidates.start[v], count = candidates.start[v + 1] - first;
      keep.assign(count, 0);
      local.resize(3 * size_t(count));
      for (const PosedMesh& pose : poses) {
        const glm::vec3 p = pose.positions[v];
        const TangentFrame frame = TangentFrame::around(pose.normals[v]);
        order.clear();
        for (uint32_t s = 0; s < count; ++s) {
          const glm::uvec3 t = candidates.triangles[candidates.list[first + s]];
          glm::vec3* q = local.data() + 3 * size_t(s);
          q[0] = frame.toLocal(pose.positions[t.x] - p);
          q[1] = frame.toLocal(pose.positions[t.y] - p);
          q[2] = frame.toLocal(pose.positions[t.z] - p);
          if (!(std::max({q[0].z, q[1].z, q[2].z}) > 0.0f)) continue;
          const glm::vec3 centroid = (q[0] + q[1] + q[2]) / 3.0f;
          order.emplace_back(glm::dot(centroid, centroid), s);
        }
        std::sort(order.begin(), order.end());
        mask.clear();
        for (const auto& [distance, s] : order) {
          std::copy_n(mask.data(), before.size(), before.data());
          const glm::vec3* q = local.data() + 3 * size_t(s);
          rasterizeBlocker(q[0], q[1], q[2], table.get(), mask);
          if (!std::equal(before.begin(), before.end(), mask.data())) keep[s] = 1;
        }
      }
      for (uint32_t s = 0; s < count; ++s)
        if (keep[s]) kept[v].push_back(candidates.list[first + s]);
    }
  });
  VertexBlockers out;
  out.triangles = candidates.triangles;
  out.groups = candidates.groups;
  for (const auto& k : kept) {
    out.list.insert(out.list.end(), k.begin(), k.end());
    out.start.push_back(uint32_t(out.list.size()));
  }
  return out;
}

ShadowHierarchy ShadowHierarchy::build(const std::vector<glm::uvec3>& fine,
                                       const std::vector<glm::uvec3>& coarse, int levels, int ring,
                                       size_t vertices, int split) {
  VS_CHECK(ring >= 1 && ring <= 2 && levels >= 0 && levels <= 6);
  VS_CHECK(split == 3 || split == 4);
  uint32_t children = 1;
  for (int l = 0; l < levels; ++l) children *= uint32_t(split);
  VS_CHECK_EQ(fine.size(), coarse.size() * children);
  ShadowHierarchy h;
  h.coarse = coarse;
  // Fine triangles around each vertex.
  std::vector<std::vector<uint32_t>> around(vertices);
  for (uint32_t t = 0; t < fine.size(); ++t)
    for (int k = 0; k < 3; ++k) around[fine[t][k]].push_back(t);
  h.ringStart.push_back(0);
  h.skipStart.push_back(0);
  std::vector<uint32_t> ringOf, parents;
  for (size_t v = 0; v < vertices; ++v) {
    ringOf = around[v];
    if (ring == 2)
      for (const uint32_t t : around[v])
        for (int k = 0; k < 3; ++k)
          ringOf.insert(ringOf.end(), around[fine[t][k]].begin(), around[fine[t][k]].end());
    std::sort(ringOf.begin(), ringOf.end());
    ringOf.erase(std::unique(ringOf.begin(), ringOf.end()), ringOf.end());
    parents.clear();
    for (const uint32_t t : ringOf) parents.push_back(t / children);
    std::sort(parents.begin(), parents.end());
    parents.erase(std::unique(parents.begin(), parents.end()), parents.end());
    h.ringTriangles.insert(h.ringTriangles.end(), ringOf.begin(), ringOf.end());
    h.skipTriangles.insert(h.skipTriangles.end(), parents.begin(), parents.end());
    h.ringStart.push_back(uint32_t(h.ringTriangles.size()));
    h.skipStart.push_back(uint32_t(h.skipTriangles.size()));
  }
  return h;
}

double ShadowHierarchy::meanBlockers() const {
  const size_t vertices = ringStart.size() - 1;
  if (vertices == 0) return 0.0;
  return double(ringTriangles.size() + vertices * coarse.size() - skipTriangles.size()) /
         double(vertices);
}

namespace {

// The vertices of the triangles t with dot(normal(t), toViewer(a)) > 0,
// where a is t's first corner.
template <class ToViewer>
std::vector<uint8_t> verticesOfTrianglesFacing(const std::vector<glm::vec3>& positions,
                                               const std::vector<glm::uvec3>& triangles,
                                               ToViewer&& toViewer) {
  std::vector<uint8_t> front(positions.size(), 0);
  for (const glm::uvec3& t : triangles) {
    const glm::vec3 a = positions[t.x];
    const glm::vec3 n = glm::cross(positions[t.y] - a, positions[t.z] - a);
    if (glm::dot(n, toViewer(a)) > 0.0f) front[t.x] = front[t.y] = front[t.z] = 1;
  }
  return front;
}

}  // namespace

std::vector<uint8_t> frontFacingVertices(const std::vector<glm::vec3>& positions,
                                         const std::vector<glm::uvec3>& triangles,
                                         const glm::vec3& view) {
  return verticesOfTrianglesFacing(positions, triangles, [&](const glm::vec3&) { return -view; });
}

std::vector<uint8_t> verticesFacing(const std::vector<glm::vec3>& positions,
                                    const std::vector<glm::uvec3>& triangles,
                                    const glm::vec3& eye) {
  return verticesOfTrianglesFacing(positions, triangles,
                                   [&](const glm::vec3& a) { return eye - a; });
}

namespace {

// Monte Carlo transfer with each unblocked ray's basis values weighted by
// weight(v, direction) (1: diffuse).
template <class Weight>
void traceTransfer(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
                   const std::vector<glm::uvec3>& triangles, uint32_t rays, int orders,
                   std::vector<float>& out, uint64_t seed, const std::vector<uint8_t>* only,
                   Weight&& weight) {
  VS_CHECK(rays >= 1 && orders >= 1 && orders <= kMaxShOrder + 1);
  if (only) VS_CHECK_EQ(only->size(), positions.size());
  const int terms = shTerms(orders);
  const auto query = makeEmbreeRayQuery(flattenMesh(positions, triangles));
  const float offset = 1e-4f * meshSize(positions);
  out.assign(positions.size() * size_t(terms), 0.0f);
  const uint32_t side = std::max<uint32_t>(1, uint32_t(std::sqrt(double(rays))));
  tbb::parallel_for(tbb::blocked_range<size_t>(0, positions.size(), 8), [&](const auto& range) {
    std::vector<Ray> batch(rays);
    std::vector<uint8_t> hit(rays);
    float y[25];
    for (size_t v = range.begin(); v != range.end(); ++v) {
      if (only && !(*only)[v]) continue;
      const TangentFrame frame = TangentFrame::around(normals[v]);
      const glm::vec3 org = positions[v] + normals[v] * offset;
      const uint64_t vertexSeed = mixBits(v ^ mixBits(seed));
      const double r1 = unitInterval(vertexSeed), r2 = unitInterval(mixBits(vertexSeed));
      for (uint32_t k = 0; k < rays; ++k) {
        double s1, s2;
        if (k < side * side) {
          s1 = (k % side + 0.5) / side;
          s2 = (double(k / side) + 0.5) / side;
        } else {
          s1 = unitInterval(mixBits(vertexSeed + k));
          s2 = unitInterval(mixBits(vertexSeed + 31 * k));
        }
        s1 = std::fmod(s1 + r1, 1.0);
        s2 = std::fmod(s2 + r2, 1.0);
        // Malley: a uniform point on the disk lifted to the hemisphere.
        const double radius = std::sqrt(s1), phi = 2.0 * std::numbers::pi * s2;
        const glm::vec3 local(float(radius * std::cos(phi)), float(radius * std::sin(phi)),
                              float(std::sqrt(std::max(0.0, 1.0 - s1))));
        batch[k] = Ray{org, frame.toWorld(local), 0.0f, INFINITY};
      }
      query->occludedMany(batch, hit);
      float* t = out.data() + v * size_t(terms);
      const float scale = float(std::numbers::pi / rays);
      for (uint32_t k = 0; k < rays; ++k) {
        if (hit[k]) continue;
        const float w = scale * weight(v, batch[k].dir);
        shEvaluate(batch[k].dir, orders, y);
        for (int i = 0; i < terms; ++i) t[i] += w * y[i];
      }
    }
  });
}

}  // namespace

void monteCarloTransfer(const std::vector<glm::vec3>& positions,
                        const std::vector<glm::vec3>& normals,
                        const std::vector<glm::uvec3>& triangles, uint32_t rays, int orders,
                        std::vector<float>& out, uint64_t seed, const std::vector<uint8_t>* only) {
  traceTransfer(positions, normals, triangles, rays, orders, out, seed, only,
                [](size_t, const glm::vec3&) { return 1.0f; });
}

void monteCarloGlossyTransfer(const std::vector<glm::vec3>& positions,
                              const std::vector<glm::vec3>& normals,
                              const std::vector<glm::uvec3>& triangles,
                              const std::vector<glm::vec3>& reflected, float exponent,
                              uint32_t rays, int orders, std::vector<float>& out, uint64_t seed,
                              const std::vector<uint8_t>* only) {
  VS_CHECK_EQ(reflected.size(), positions.size());
  const float norm = float((exponent + 1.0) / (2.0 * std::numbers::pi));
  traceTransfer(positions, normals, triangles, rays, orders, out, seed, only,
                [&](size_t v, const glm::vec3& d) {
                  return norm * std::pow(std::max(0.0f, glm::dot(d, reflected[v])), exponent);
                });
}

double meanRelativeL2(const std::vector<float>& a, const std::vector<float>& b, int terms) {
  VS_CHECK_EQ(a.size(), b.size());
  double sum = 0.0;
  size_t count = 0;
  for (size_t v = 0; v + size_t(terms) <= a.size(); v += size_t(terms)) {
    double num = 0.0, den = 0.0;
    for (int i = 0; i < terms; ++i) {
      const double d = double(a[v + size_t(i)]) - b[v + size_t(i)];
      num += d * d;
      den += double(b[v + size_t(i)]) * b[v + size_t(i)];
    }
    if (den > 0.0) {
      sum += std::sqrt(num / den);
      ++count;
    }
  }
  return count ? sum / double(count) : 0.0;
}

}  // namespace vistream
