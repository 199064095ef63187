// EmbreeRayQuery: the production back end, on Embree 3.
//
// One scene per query object on a process-wide device, holding one triangle
// geometry (the batched query: one per batch, in a two-level scene of build
// quality low, with RTC_SCENE_FLAG_DYNAMIC) built with
//  - RTC_SCENE_FLAG_ROBUST: Embree then intersects with its Pluecker test
//    (kernels/geometry/triangle_intersector_pluecker.h), whose edge function
//    for an edge shared by two triangles is computed from the same two
//    vertices in both, so the two values are exact negations, and which
//    accepts a hit on the edge (|edge function| <= 1 ulp of their sum).
//    Closed and watertight, like the oracle's double-precision test.
//  - RTC_BUILD_QUALITY_HIGH: spatial-split BVH; a triangle may then sit in
//    several leaves, which allHits has to undo.
//
// How the shared semantics of ray_query.h are met:
//  - Degenerate triangles are left out of the geometry: the index buffer lists
//    only the others and each geometry's primToTriangle maps Embree's
//    (geomID, primID) back to the triangle index. They are
//    never hit and cost nothing at query time, with no filter.
//  - [tnear, tfar] is widened by kBoundSlack (relative) before Embree sees it
//    and the reported t is clamped back into it: Embree computes
//    t = rcp(den) * T in float, which can put a hit that lies exactly on a
//    bound an ulp or two outside it.
//  - Ties: Embree returns whichever of two equally near triangles it meets
//    first. After the nearest hit at t* is found, a second query over the
//    short segment t* +- tieWindow() runs a context filter that sees every
//    triangle there, rejects each so traversal goes on, and keeps the
//    smallest index. The window covers Embree's float error in t, so the
//    triangles around a shared edge or vertex (whose t agree exactly in exact
//    arithmetic) always compete. Cost: one short traversal per hit ray.
//  - allHits: a context filter appends every candidate to a vector carried by
//    an extended RTCIntersectContext and rejects it so traversal goes on;
//    duplicates from spatial splits are removed, then hits are sorted.
//  - Zero direction components: Embree's box test replaces a direction
//    component below 1e-18 in magnitude by +1e-18 (rcp_safe), so for a ray
//    with dir.x == 0 whose origin lies exactly on a box's upper x face it
//    computes the exit distance (hi.x - org.x) * 1e18 = 0 and skips the box:
//    a vertical ray exactly through a grid vertex would miss the triangles on
//    the low side. Such rays are traversed once per sign of each zero
//    component (at most four times): as given, which keeps boxes touching
//    the origin from above, and with the component set to -kZeroTilt, which
//    keeps those touching it from below. For directions longer than about
//    1e-10 the tilt is far below the float resolution of any edge function
//    or t, so every variant computes the same hits, and their union is
//    complete.
//  - Batches use Embree's stream API (rtcIntersect1M, rtcOccluded1M) in
//    chunks of kStreamChunk rays, with the tie pass as a second stream.
//  - The normal is Embree's unnormalised geometric normal Ng, which is the
//    contract's (v1-v0) x (v2-v0) up to float rounding (Embree picks the most
//    accurate pair of edges for the cross product).
#include "common/raycast/embree_ray_query.h"

#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <type_traits>

#include "common/core/check.h"
#include "common/raycast/ray_query.h"

namespace vistream {
namespace {

// Relative widening of [tnear, tfar]: 4 to 8 float ulps, a few times the error
// of Embree's t = rcp(den) * T (rcp with one Newton step) for a hit exactly on
// a bound.
constexpr float kBoundSlack = 0x1p-21f;

// Relative half-width of the tie window: 32 float ulps of the hit's distance
// scale (see tieWindow()).
constexpr float kTieWindow = 0x1p-18f;

// Stand-in for a zero direction component in the variant that keeps boxes
// touching the origin from below: just beyond Embree's min_rcp_input (1e-18).
constexpr float kZeroTilt = 2e-18f;

// Rays per stream call: the RTCRayHit arrays stay on the stack (128 * 80 bytes).
constexpr size_t kStreamChunk = 128;

std::atomic<uint64_t> gEmbreeErrors{0};

const char* errorName(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE:
      return "none";
    case RTC_ERROR_UNKNOWN:
      return "unknown";
    case RTC_ERROR_INVALID_ARGUMENT:
      return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION:
      return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY:
      return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU:
      return "unsupported CPU";
    case RTC_ERROR_CANCELLED:
      return "cancelled";
  }
  return "unrecognised";
}

void reportEmbreeError(void*, RTCError code, const char* message) {
  gEmbreeErrors.fetch_add(1, std::memory_order_relaxed);
  spdlog::error("Embree: {} ({})", message ? message : "no message", errorName(code));
}

// One Embree device shared by every live EmbreeRayQuery: a device owns a
// thread pool and its start-up cost, neither worth paying per scene. Released
// when the last query using it goes.
std::shared_ptr<RTCDeviceTy> acquireDevice() {
  static std::mutex mutex;  // guards `shared`
  static std::weak_ptr<RTCDeviceTy> shared;
  std::lock_guard lock(mutex);
  if (std::shared_ptr<RTCDeviceTy> device = shared.lock()) return device;
  RTCDevice raw = rtcNewDevice(nullptr);
  if (!raw) {
    throw std::runtime_error(std::string("Embree: cannot create a device: ") +
                             errorName(rtcGetDeviceError(nullptr)));
  }
  rtcSetDeviceErrorFunction(raw, reportEmbreeError, nullptr);
  std::shared_ptr<RTCDeviceTy> device(raw, [](RTCDevice d) { rtcReleaseDevice(d); });
  shared = device;
  return device;
}

bool hasZeroComponent(const glm::vec3& dir) {
  return dir.x == 0.0f || dir.y == 0.0f || dir.z == 0.0f;
}

// The rays Embree must traverse to answer `ray`: itself, plus for each zero
// direction component a copy with that component at -kZeroTilt (see the
// header comment). Returns how many of `variants` are filled: 1, 2 or 4.
int traversalVariants(const Ray& ray, std::array<Ray, 4>& variants) {
  variants[0] = ray;
  int count = 1;
  for (int axis = 0; axis < 3; ++axis) {
    if (ray.dir[axis] != 0.0f) continue;
    for (int k = 0; k < count; ++k) {
      variants[size_t(count + k)] = variants[size_t(k)];
      variants[size_t(count + k)].dir[axis] = -kZeroTilt;
    }
    count *= 2;  // at most two components are zero in a traceable ray
  }
  return count;
}

float widenDown(float t) {
  return t - std::abs(t) * kBoundSlack;
}
float widenUp(float t) {
  return t + std::abs(t) * kBoundSlack;
}  // inf stays inf

RTCRay toEmbreeRay(const Ray& ray, float tnear, float tfar, unsigned id) {
  RTCRay r;
  r.org_x = ray.org.x;
  r.org_y = ray.org.y;
  r.org_z = ray.org.z;
  r.tnear = tnear;
  r.dir_x = ray.dir.x;
  r.dir_y = ray.dir.y;
  r.dir_z = ray.dir.z;
  r.time = 0.0f;
  r.tfar = tfar;
  r.mask = 0xffffffffu;
  r.id = id;
  r.flags = 0;
  return r;
}

RTCRay toEmbreeRay(const Ray& ray, unsigned id) {
  return toEmbreeRay(ray, widenDown(ray.tnear), widenUp(ray.tfar), id);
}

RTCRayHit withEmptyHit(const RTCRay& ray) {
  RTCRayHit rh;
  rh.ray = ray;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rh.hit.u = rh.hit.v = 0.0f;
  rh.hit.Ng_x = rh.hit.Ng_y = rh.hit.Ng_z = 0.0f;
  return rh;
}

// A hit as Embree reports it: geometry and primitive ID, and the triangle
// index they stand for (filled in by the query, which knows the mapping).
struct PrimHit {
  unsigned geom = RTC_INVALID_GEOMETRY_ID, prim = RTC_INVALID_GEOMETRY_ID;
  uint32_t triangle = kNoHit;
  float t = 0.0f, u = 0.0f, v = 0.0f;
  glm::vec3 ng{0.0f};

  bool valid() const { return triangle != kNoHit; }
};

PrimHit fromEmbree(const RTCRayHit& rh) {
  return PrimHit{rh.hit.geomID,
                 rh.hit.primID,
                 kNoHit,
                 rh.ray.tfar,
                 rh.hit.u,
                 rh.hit.v,
                 glm::vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z)};
}

// Candidate i of a filter call; Embree puts the candidate's t in the ray's tfar.
PrimHit fromFilter(const RTCFilterFunctionNArguments* args, unsigned i) {
  const unsigned n = args->N;
  return PrimHit{RTCHitN_geomID(args->hit, n, i),
                 RTCHitN_primID(args->hit, n, i),
                 kNoHit,
                 RTCRayN_tfar(args->ray, n, i),
                 RTCHitN_u(args->hit, n, i),
                 RTCHitN_v(args->hit, n, i),
                 glm::vec3(RTCHitN_Ng_x(args->hit, n, i), RTCHitN_Ng_y(args->hit, n, i),
                           RTCHitN_Ng_z(args->hit, n, i))};
}

// One Embree triangle geometry: its own copy of the vertices and the
// triangle index of each of its primitives.
struct Mesh {
  std::vector<float> vertices;           // 3 floats a vertex + 1 float of padding
  std::vector<glm::uvec3> indices;       // into vertices, one per primitive
  std::vector<uint32_t> primToTriangle;  // primitive -> triangle index
};

using Meshes = std::vector<std::unique_ptr<Mesh>>;  // by geomID; null where detached

uint32_t triangleOfHit(const Meshes& meshes, unsigned geom, unsigned prim) {
  return meshes[geom]->primToTriangle[prim];
}

// Context filters. Embree passes the filter the RTCIntersectContext pointer
// it was given, so a struct that starts with one carries extra state along
// (the extension pattern of Embree's own tutorials).

// Tie pass: keeps, per ray (by RTCRay::id), the hit with the smallest triangle index.
struct TieContext {
  RTCIntersectContext embree;  // must stay the first member
  PrimHit* best;               // indexed by ray id
  const Meshes* meshes;
};
static_assert(std::is_standard_layout_v<TieContext>);

// Keeps, per ray, the candidate with the smallest triangle index.
void keepSmallestTriangle(const RTCFilterFunctionNArguments* args) {
  const TieContext* ctx = reinterpret_cast<const TieContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    PrimHit& best = ctx->best[RTCRayN_id(args->ray, args->N, i)];
    const uint32_t triangle = triangleOfHit(*ctx->meshes, RTCHitN_geomID(args->hit, args->N, i),
                                            RTCHitN_primID(args->hit, args->N, i));
    if (triangle < best.triangle) {
      best = fromFilter(args, i);
      best.triangle = triangle;
    }
    args->valid[i] = 0;  // reject: traversal goes on to the other candidates
  }
}

// allHits: appends every candidate of the single ray and rejects it.
struct CollectContext {
  RTCIntersectContext embree;  // must stay the first member
  std::vector<PrimHit>* hits;
};
static_assert(std::is_standard_layout_v<CollectContext>);

void collectAll(const RTCFilterFunctionNArguments* args) {
  const CollectContext* ctx = reinterpret_cast<const CollectContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    ctx->hits->push_back(fromFilter(args, i));
    args->valid[i] = 0;
  }
}

// The queries of both back ends (one static geometry, or one geometry per
// batch): an Embree scene whose geometries are Meshes, indexed by geomID.
template <class Interface>
class EmbreeScene : public Interface {
 public:
  EmbreeScene() : device_(acquireDevice()) {}
  ~EmbreeScene() override {
    if (scene_) rtcReleaseScene(scene_);
  }
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  const char* name() const override { return "embree"; }

  Hit firstHit(const Ray& ray) const override {
    if (!isTraceable(ray)) return Hit{};
    std::array<Ray, 4> variants;
    const int count = traversalVariants(ray, variants);
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    PrimHit best;
    for (int k = 0; k < count; ++k) {
      RTCRayHit rh = withEmptyHit(toEmbreeRay(variants[size_t(k)], 0));
      rtcIntersect1(scene_, &context, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
      PrimHit h = fromEmbree(rh);
      h.triangle = triangleOfHit(meshes_, h.geom, h.prim);
      if (!best.valid() || h.t < best.t || (h.t == best.t && h.triangle < best.triangle)) best = h;
    }
    if (!best.valid()) return Hit{};

    const PrimHit nearest = best;  // the tie window stays centred on it
    TieContext tie = tieContext(&best);
    for (int k = 0; k < count; ++k) {
      RTCRayHit window = withEmptyHit(tieRay(variants[size_t(k)], nearest, 0));
      rtcIntersect1(scene_, &tie.embree, &window);
    }
    return toHit(ray, best);
  }

  bool occluded(const Ray& ray) const override {
    if (!isTraceable(ray)) return false;
    std::array<Ray, 4> variants;
    const int count = traversalVariants(ray, variants);
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    for (int k = 0; k < count; ++k) {
      RTCRay r = toEmbreeRay(variants[size_t(k)], 0);
      rtcOccluded1(scene_, &context, &r);
      if (r.tfar == -std::numeric_limits<float>::infinity()) return true;
    }
    return false;
  }

  void allHits(const Ray& ray, std::vector<Hit>& hits) const override {
    hits.clear();
    if (!isTraceable(ray)) return;
    std::vector<PrimHit> found;
    CollectContext collect;
    rtcInitIntersectContext(&collect.embree);
    collect.embree.filter = collectAll;
    collect.hits = &found;
    std::array<Ray, 4> variants;
    const int count = traversalVariants(ray, variants);
    for (int k = 0; k < count; ++k) {
      RTCRayHit rh = withEmptyHit(toEmbreeRay(variants[size_t(k)], 0));
      rtcIntersect1(scene_, &collect.embree, &rh);
    }
    for (PrimHit& h : found) h.triangle = triangleOfHit(meshes_, h.geom, h.prim);

    // A triangle split into several leaves is reported once per leaf, with
    // the same t (same arithmetic on the same vertices): keep one.
    std::sort(found.begin(), found.end(), [](const PrimHit& a, const PrimHit& b) {
      return a.triangle != b.triangle ? a.triangle < b.triangle : a.t < b.t;
    });
    found.erase(
        std::unique(found.begin(), found.end(),
                    [](const PrimHit& a, const PrimHit& b) { return a.triangle == b.triangle; }),
        found.end());
    hits.reserve(found.size());
    for (const PrimHit& h : found) hits.push_back(toHit(ray, h));
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
      return a.t != b.t ? a.t < b.t : a.triangle < b.triangle;
    });
  }

  void firstHits(std::span<const Ray> rays, std::span<Hit> hits) const override {
    VS_CHECK_EQ(rays.size(), hits.size());
    std::array<RTCRayHit, kStreamChunk> stream;
    std::array<PrimHit, kStreamChunk> best;
    for (size_t begin = 0; begin < rays.size(); begin += kStreamChunk) {
      const size_t count = std::min(kStreamChunk, rays.size() - begin);
      const Ray* chunk = rays.data() + begin;
      Hit* out = hits.data() + begin;

      // Nearest hits. Untraceable rays stay out of the stream, and so do
      // rays with a zero direction component, which need several traversals.
      unsigned traced = 0;
      for (size_t i = 0; i < count; ++i) {
        out[i] = Hit{};
        best[i] = PrimHit{};
        if (!isTraceable(chunk[i])) continue;
        if (hasZeroComponent(chunk[i].dir))
          out[i] = firstHit(chunk[i]);
        else
          stream[traced++] = withEmptyHit(toEmbreeRay(chunk[i], unsigned(i)));
      }
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      rtcIntersect1M(scene_, &context, stream.data(), traced, sizeof(RTCRayHit));

      // Tie pass over the rays that hit, as a second stream.
      unsigned hitCount = 0;
      for (unsigned k = 0; k < traced; ++k) {
        const RTCRayHit& rh = stream[k];
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
        const unsigned i = rh.ray.id;
        best[i] = fromEmbree(rh);
        best[i].triangle = triangleOfHit(meshes_, best[i].geom, best[i].prim);
        stream[hitCount++] = withEmptyHit(tieRay(chunk[i], best[i], i));
      }
      TieContext tie = tieContext(best.data());
      rtcIntersect1M(scene_, &tie.embree, stream.data(), hitCount, sizeof(RTCRayHit));

      for (size_t i = 0; i < count; ++i)
        if (best[i].valid()) out[i] = toHit(chunk[i], best[i]);
    }
  }

  void occludedMany(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
    VS_CHECK_EQ(rays.size(), occluded.size());
    std::array<RTCRay, kStreamChunk> stream;
    for (size_t begin = 0; begin < rays.size(); begin += kStreamChunk) {
      const size_t count = std::min(kStreamChunk, rays.size() - begin);
      unsigned traced = 0;
      for (size_t i = 0; i < count; ++i) {
        const Ray& ray = rays[begin + i];
        occluded[begin + i] = 0;
        if (!isTraceable(ray)) continue;
        if (hasZeroComponent(ray.dir))
          occluded[begin + i] = this->occluded(ray) ? 1 : 0;
        else
          stream[traced++] = toEmbreeRay(ray, unsigned(i));
      }
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      rtcOccluded1M(scene_, &context, stream.data(), traced, sizeof(RTCRay));
      for (unsigned k = 0; k < traced; ++k)
        if (stream[k].tfar == -std::numeric_limits<float>::infinity())
          occluded[begin + stream[k].id] = 1;
    }
  }

 protected:
  // A new empty scene: static (one high-quality BVH) or dynamic (a two-level
  // BVH, whose commit rebuilds only the geometries that changed).
  void newScene(bool dynamic) {
    rtcGetDeviceError(device_.get());  // clear this thread's error code
    scene_ = rtcNewScene(device_.get());
    RTCSceneFlags flags =
        RTCSceneFlags(RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);
    if (dynamic) flags = RTCSceneFlags(flags | RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneFlags(scene_, flags);
    // RTC_BUILD_QUALITY_LOW selects Embree's two-level structure; each
    // geometry's own BVH is still built with its geometry's quality.
    rtcSetSceneBuildQuality(scene_, dynamic ? RTC_BUILD_QUALITY_LOW : RTC_BUILD_QUALITY_HIGH);
  }

  // Attaches `mesh` (non-empty) as a new geometry; returns its geomID.
  unsigned attach(std::unique_ptr<Mesh> mesh) {
    VS_CHECK(!mesh->indices.empty());
    RTCGeometry geometry = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
    const size_t vertexCount = (mesh->vertices.size() - 1) / 3;
    rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                               mesh->vertices.data(), 0, 3 * sizeof(float), vertexCount);
    rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                               mesh->indices.data(), 0, sizeof(glm::uvec3), mesh->indices.size());
    rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_HIGH);
    rtcCommitGeometry(geometry);
    const unsigned id = rtcAttachGeometry(scene_, geometry);
    rtcReleaseGeometry(geometry);
    if (meshes_.size() <= id) meshes_.resize(size_t(id) + 1);
    meshes_[id] = std::move(mesh);
    return id;
  }

  // Detaches a geometry; its Mesh lives until the next commit, which ends
  // the old BVH's use of it.
  void detach(unsigned id) {
    rtcDetachGeometry(scene_, id);
    retired_.push_back(std::move(meshes_[id]));
  }
  const Mesh& mesh(unsigned id) const { return *meshes_[id]; }

  // Commits the scene; throws std::runtime_error naming what failed.
  void commitScene(size_t triangles) {
    rtcCommitScene(scene_);
    retired_.clear();
    const RTCError error = rtcGetDeviceError(device_.get());
    if (error != RTC_ERROR_NONE)
      throw std::runtime_error(fmt::format("Embree: building the scene of {} triangles failed: {}",
                                           triangles, errorName(error)));
  }

 private:
  TieContext tieContext(PrimHit* best) const {
    TieContext tie;
    rtcInitIntersectContext(&tie.embree);
    tie.embree.filter = keepSmallestTriangle;
    tie.best = best;
    tie.meshes = &meshes_;
    return tie;
  }

  // Half-width of the tie window around a hit at t: the float error of
  // Embree's t grows with the distance from the ray origin to the vertices of
  // the triangles involved, i.e. with t |dir| plus the size of the triangle.
  float tieWindow(const Ray& ray, const PrimHit& hit) const {
    const Mesh& mesh = *meshes_[hit.geom];
    const glm::uvec3 corners = mesh.indices[hit.prim];
    Box3f bounds;
    for (int k = 0; k < 3; ++k) {
      const float* v = &mesh.vertices[3 * size_t(corners[k])];
      bounds.extend(glm::vec3(v[0], v[1], v[2]));
    }
    return kTieWindow * (std::abs(hit.t) + glm::length(bounds.extent()) / glm::length(ray.dir));
  }

  // The segment of `ray` around `hit` where another triangle ties with it,
  // never beyond the (widened) bounds of the query.
  RTCRay tieRay(const Ray& ray, const PrimHit& hit, unsigned id) const {
    const float w = tieWindow(ray, hit);
    return toEmbreeRay(ray, std::max(widenDown(ray.tnear), hit.t - w),
                       std::min(widenUp(ray.tfar), hit.t + w), id);
  }

  static Hit toHit(const Ray& ray, const PrimHit& h) {
    Hit hit;
    hit.triangle = h.triangle;
    hit.t = std::clamp(h.t, ray.tnear, ray.tfar);
    hit.u = h.u;
    hit.v = h.v;
    hit.normal = h.ng;
    return hit;
  }

  std::shared_ptr<RTCDeviceTy> device_;
  RTCScene scene_ = nullptr;
  Meshes meshes_;
  std::vector<std::unique_ptr<Mesh>> retired_;  // detached since the last commit
};

// A copy of triangles [first, first + count) that are not degenerate, as one
// Mesh; its vertices are those triangles' corners.
std::unique_ptr<Mesh> meshOf(const FlatTriangles& triangles, uint32_t first, uint32_t count) {
  auto mesh = std::make_unique<Mesh>();
  // Embree reads the last vertex with a 16-byte load: one float of padding.
  mesh->vertices.resize(9 * size_t(count) + 1, 0.0f);
  if (count > 0)
    std::memcpy(mesh->vertices.data(), triangles.positions.data() + 3 * size_t(first),
                3 * size_t(count) * sizeof(glm::vec3));
  for (uint32_t i = 0; i < count; ++i) {
    const uint32_t t = first + i;
    if (triangles.degenerate[t]) continue;
    mesh->indices.push_back(glm::uvec3(3 * i, 3 * i + 1, 3 * i + 2));
    mesh->primToTriangle.push_back(t);
  }
  return mesh;
}

class EmbreeRayQuery final : public EmbreeScene<RayQuery> {
 public:
  explicit EmbreeRayQuery(const FlatTriangles& triangles) {
    const size_t n = triangles.size();
    VS_CHECK_EQ(triangles.positions.size(), 3 * n);
    VS_CHECK_EQ(triangles.degenerate.size(), n);
    // Embree indexes vertices with 32 bits.
    VS_CHECK_LE(triangles.positions.size(), size_t(std::numeric_limits<uint32_t>::max()));
    newScene(/*dynamic=*/false);
    std::unique_ptr<Mesh> mesh = meshOf(triangles, 0, uint32_t(n));
    if (!mesh->indices.empty()) attach(std::move(mesh));
    commitScene(n);
  }
};

// Batches as contiguous ranges of triangle indices, each its own geometry.
// Removing triangles rebuilds the geometry of their batch from its own mesh
// without them (or detaches it when nothing is left); commit() lets Embree's
// two-level BVH rebuild only what changed.
class EmbreeBatchedRayQuery final : public EmbreeScene<BatchedRayQuery> {
 public:
  EmbreeBatchedRayQuery() { newScene(/*dynamic=*/true); }

  void addBatch(const FlatTriangles& triangles, uint32_t first, uint32_t count) override {
    VS_CHECK_EQ(triangles.positions.size(), 3 * triangles.size());
    VS_CHECK_EQ(triangles.degenerate.size(), triangles.size());
    VS_CHECK_LE(size_t(first) + count, triangles.size());
    if (count == 0) return;
    // Ranges must not overlap: the next batch starts at or after this one's end.
    auto next = batches_.lower_bound(first);
    VS_CHECK(next == batches_.end() || next->first >= first + count);
    if (next != batches_.begin()) {
      const auto before = std::prev(next);
      VS_CHECK_LE(before->first + before->second.count, first);
    }
    Batch b;
    b.count = count;
    b.removed.assign(count, 0);
    std::unique_ptr<Mesh> m = meshOf(triangles, first, count);
    b.live = m->indices.size();
    if (b.live == 0) return;  // only degenerate triangles: nothing to hit or remove
    b.geom = attach(std::move(m));
    live_ += b.live;
    batches_.emplace(first, std::move(b));
  }

  void removeTriangles(std::span<const uint32_t> triangles) override {
    std::vector<uint32_t> changed;  // first triangle of each batch touched
    for (const uint32_t t : triangles) {
      auto it = batches_.upper_bound(t);
      if (it == batches_.begin()) continue;
      --it;
      Batch& b = it->second;
      if (t >= it->first + b.count || b.removed[t - it->first]) continue;
      b.removed[t - it->first] = 1;
      changed.push_back(it->first);
    }
    std::sort(changed.begin(), changed.end());
    changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
    for (const uint32_t first : changed) {
      Batch& b = batches_.at(first);
      // The batch's geometry again, without the triangles removed.
      const Mesh& old = mesh(b.geom);
      auto rebuilt = std::make_unique<Mesh>();
      rebuilt->vertices = old.vertices;
      for (size_t p = 0; p < old.indices.size(); ++p)
        if (!b.removed[old.primToTriangle[p] - first]) {
          rebuilt->indices.push_back(old.indices[p]);
          rebuilt->primToTriangle.push_back(old.primToTriangle[p]);
        }
      detach(b.geom);
      b.geom = RTC_INVALID_GEOMETRY_ID;
      live_ -= b.live;
      b.live = rebuilt->indices.size();
      live_ += b.live;
      if (b.live > 0)
        b.geom = attach(std::move(rebuilt));
      else
        batches_.erase(first);
    }
  }

  void commit() override { commitScene(live_); }
  size_t batchCount() const override { return batches_.size(); }

 private:
  struct Batch {
    uint32_t count = 0;
    std::vector<uint8_t> removed;  // per triangle of the range
    size_t live = 0;               // primitives attached
    unsigned geom = RTC_INVALID_GEOMETRY_ID;
  };

  std::map<uint32_t, Batch> batches_;  // by first triangle index
  size_t live_ = 0;
};

}  // namespace

uint64_t embreeErrorCount() {
  return gEmbreeErrors.load(std::memory_order_relaxed);
}

std::unique_ptr<RayQuery> makeEmbreeRayQuery(const FlatTriangles& triangles) {
  return std::make_unique<EmbreeRayQuery>(triangles);
}

std::unique_ptr<BatchedRayQuery> makeBatchedEmbreeRayQuery() {
  return std::make_unique<EmbreeBatchedRayQuery>();
}

}  // namespace vistream
