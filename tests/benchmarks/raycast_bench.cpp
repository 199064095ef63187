// Ray-casting throughput of the ray-query back ends on the procedural cities,
// and the build time of their acceleration structures.
//
// Scenes: generate("city1") (about 42 thousand triangles) and
// generate("bigcity") (about 2 million), through toScene() and flattenScene(),
// built once per process. Rays: from eye height (1.7 m) above street points
// (a downward ray finds the ground within 2 m and an upward ray finds open
// sky, so the eye is in a street or courtyard, not inside a building), in
// uniformly random directions with tfar = infinity; a fixed pool of 65536
// rays walked in batches.
//
// Units: items_per_second is rays/s (single thread, process CPU time). On
// city1 the brute-force oracle is measured in the same run on a few rays per
// iteration, and every other city1 row reports x_bruteforce, its speed-up over
// the oracle on the same query type (both timed in thread CPU time). Build
// rows report ms_per_Mtri (wall clock, all cores) and Mtri.
//
//   bench_raycast --benchmark_filter=city1        # skip the 2M-triangle city
#include <benchmark/benchmark.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "common/core/check.h"
#include "common/core/timer.h"
#include "common/generate/generate.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "common/spatial/kdtree.h"
#include "tests/common/support/triangle_soups.h"

namespace vistream {
namespace {

constexpr float kEyeHeight = 1.7f;  // metres above the ground
constexpr size_t kRayPool = size_t(1) << 16;
constexpr size_t kRaysPerEye = 8;       // directions cast from each street point
constexpr size_t kBatch = 1024;         // rays per iteration for the fast back ends
constexpr size_t kBruteForceBatch = 8;  // the oracle tests every triangle per ray
constexpr size_t kBaselineRays = 64;    // rays timed once for the x_bruteforce ratio

// CPU time of the calling thread: the ray queries are single-threaded, and
// unlike wall-clock time this ignores other processes sharing the machine.
double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

enum class QueryKind { FirstHit, FirstHitStream, Occluded, OccludedStream, AllHits };

const char* kindName(QueryKind kind) {
  switch (kind) {
    case QueryKind::FirstHit:
      return "FirstHit";
    case QueryKind::FirstHitStream:
      return "FirstHitStream";
    case QueryKind::Occluded:
      return "Occluded";
    case QueryKind::OccludedStream:
      return "OccludedStream";
    case QueryKind::AllHits:
      return "AllHits";
  }
  return "?";
}

using testing::randomDirection;

// Eye-height rays from street points of a city with its ground at the
// lowest y of the scene (see the file comment).
std::vector<Ray> streetRays(const FlatTriangles& triangles, const RayQuery& query, size_t count,
                            uint32_t seed) {
  Box3f bounds;
  for (const glm::vec3& p : triangles.positions) bounds.extend(p);
  VS_CHECK(!bounds.empty());
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<Ray> rays;
  rays.reserve(count);
  size_t attempts = 0;
  while (rays.size() < count) {
    VS_CHECK_LT(attempts++, 100 * count);  // a city has streets
    const glm::vec3 eye(glm::mix(bounds.lo.x, bounds.hi.x, unit(rng)), bounds.lo.y + kEyeHeight,
                        glm::mix(bounds.lo.z, bounds.hi.z, unit(rng)));
    const Ray down{eye, glm::vec3(0, -1, 0), 0.0f, 2.0f};
    const Ray up{eye, glm::vec3(0, 1, 0)};
    if (!query.firstHit(down).valid() || query.occluded(up)) continue;
    for (size_t k = 0; k < kRaysPerEye && rays.size() < count; ++k)
      rays.push_back(Ray{eye, randomDirection(rng)});
  }
  return rays;
}

struct City {
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> embree;
  std::unique_ptr<RayQuery> kdtree;      // built on first use
  std::unique_ptr<RayQuery> bruteForce;  // city1 only
  std::vector<Ray> rays;
  std::map<QueryKind, double> bruteForceSecondsPerRay;  // city1 only, measured on first use

  double megaTriangles() const { return double(triangles.size()) * 1e-6; }
};

// Google Benchmark runs one benchmark at a time, so the lazily filled cache
// needs no lock. Leaked on purpose: Embree scenes must not be released during
// static destruction, after TBB may already be gone.
City& city(const std::string& type) {
  static auto* cache = new std::map<std::string, std::unique_ptr<City>>();
  std::unique_ptr<City>& slot = (*cache)[type];
  if (!slot) {
    slot = std::make_unique<City>();
    slot->triangles = flattenScene(toScene(generate(type)));
    slot->embree = makeEmbreeRayQuery(slot->triangles);
    slot->rays = streetRays(slot->triangles, *slot->embree, kRayPool, 42);
  }
  return *slot;
}

const RayQuery& backEnd(City& c, const std::string& name) {
  if (name == "embree") return *c.embree;
  if (name == "kdtree") {
    if (!c.kdtree) c.kdtree = makeKdTreeRayQuery(c.triangles);
    return *c.kdtree;
  }
  if (!c.bruteForce) c.bruteForce = makeBruteForceRayQuery(c.triangles);
  return *c.bruteForce;
}

// Runs `kind` over rays[begin, begin + count) and returns a checksum (hits),
// so the work cannot be optimised away.
size_t castBatch(const RayQuery& query, QueryKind kind, std::span<const Ray> rays,
                 std::vector<Hit>& hits, std::vector<uint8_t>& occluded, std::vector<Hit>& all) {
  size_t found = 0;
  switch (kind) {
    case QueryKind::FirstHit:
      for (size_t i = 0; i < rays.size(); ++i) {
        hits[i] = query.firstHit(rays[i]);
        found += hits[i].valid() ? 1 : 0;
      }
      break;
    case QueryKind::FirstHitStream:
      query.firstHits(rays, std::span<Hit>(hits.data(), rays.size()));
      for (size_t i = 0; i < rays.size(); ++i) found += hits[i].valid() ? 1 : 0;
      break;
    case QueryKind::Occluded:
      for (const Ray& ray : rays) found += query.occluded(ray) ? 1 : 0;
      break;
    case QueryKind::OccludedStream:
      query.occludedMany(rays, std::span<uint8_t>(occluded.data(), rays.size()));
      for (size_t i = 0; i < rays.size(); ++i) found += occluded[i];
      break;
    case QueryKind::AllHits:
      for (const Ray& ray : rays) {
        query.allHits(ray, all);
        found += all.size();
      }
      break;
  }
  return found;
}

// Seconds per ray of the brute-force oracle on city1 for `kind`, timed once.
double bruteForceSecondsPerRay(City& c, QueryKind kind) {
  const QueryKind baseKind = kind == QueryKind::FirstHitStream   ? QueryKind::FirstHit
                             : kind == QueryKind::OccludedStream ? QueryKind::Occluded
                                                                 : kind;
  auto it = c.bruteForceSecondsPerRay.find(baseKind);
  if (it != c.bruteForceSecondsPerRay.end()) return it->second;
  const RayQuery& oracle = backEnd(c, "bruteforce");
  std::vector<Hit> hits(kBaselineRays), all;
  std::vector<uint8_t> occluded(kBaselineRays);
  const double start = threadCpuSeconds();
  benchmark::DoNotOptimize(castBatch(
      oracle, baseKind, std::span<const Ray>(c.rays.data(), kBaselineRays), hits, occluded, all));
  const double seconds = (threadCpuSeconds() - start) / double(kBaselineRays);
  c.bruteForceSecondsPerRay[baseKind] = seconds;
  return seconds;
}

void castRays(benchmark::State& state, const std::string& sceneType, const std::string& name,
              QueryKind kind) {
  City& c = city(sceneType);
  const RayQuery& query = backEnd(c, name);
  const bool bruteForce = name == "bruteforce";
  const size_t batch = bruteForce ? kBruteForceBatch : kBatch;
  std::vector<Hit> hits(batch), all;
  std::vector<uint8_t> occluded(batch);
  size_t offset = 0, found = 0;
  const double start = threadCpuSeconds();
  for (auto _ : state) {
    found += castBatch(query, kind, std::span<const Ray>(c.rays.data() + offset, batch), hits,
                       occluded, all);
    offset = (offset + batch) % c.rays.size();
  }
  const double seconds = threadCpuSeconds() - start;
  benchmark::DoNotOptimize(found);
  const int64_t rays = state.iterations() * int64_t(batch);
  state.SetItemsProcessed(rays);
  state.counters["Mtri"] = c.megaTriangles();
  state.counters[kind == QueryKind::AllHits ? "hits_per_ray" : "hit_fraction"] =
      double(found) / double(std::max<int64_t>(rays, 1));
  if (sceneType == "city1" && !bruteForce) {
    // Speed-up over the oracle: (rays/s) * (oracle s/ray).
    state.counters["x_bruteforce"] = double(rays) / seconds * bruteForceSecondsPerRay(c, kind);
  }
}

void buildStructure(benchmark::State& state, const std::string& sceneType,
                    const std::string& structure) {
  City& c = city(sceneType);
  double totalMs = 0.0;
  for (auto _ : state) {
    if (structure == "embree") {
      const Stopwatch watch;
      std::unique_ptr<RayQuery> query = makeEmbreeRayQuery(c.triangles);
      totalMs += watch.ms();
      benchmark::DoNotOptimize(query.get());
      state.PauseTiming();  // releasing the scene is not building it
      query.reset();
      state.ResumeTiming();
    } else {
      const Stopwatch watch;
      KdTree tree = KdTree::buildOverTriangles(c.triangles);
      totalMs += watch.ms();
      benchmark::DoNotOptimize(tree.nodes().data());
      state.counters["nodes"] = double(tree.stats().nodes);
      state.PauseTiming();
      tree = KdTree();
      state.ResumeTiming();
    }
  }
  state.counters["Mtri"] = c.megaTriangles();
  state.counters["ms_per_Mtri"] =
      totalMs / double(std::max<int64_t>(state.iterations(), 1)) / c.megaTriangles();
}

void registerBenchmarks() {
  const std::vector<QueryKind> kinds = {QueryKind::FirstHit, QueryKind::FirstHitStream,
                                        QueryKind::Occluded, QueryKind::OccludedStream,
                                        QueryKind::AllHits};
  for (const std::string scene : {"city1", "bigcity"}) {
    for (const std::string structure : {"embree", "kdtree"}) {
      benchmark::RegisterBenchmark(("Build/" + structure + "/" + scene).c_str(), buildStructure,
                                   scene, structure)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime()
          ->Iterations(scene == "bigcity" ? 1 : 5);
    }
    std::vector<std::string> backEnds = {"embree", "kdtree"};
    if (scene == "city1") backEnds.insert(backEnds.begin(), "bruteforce");
    for (QueryKind kind : kinds) {
      for (const std::string& name : backEnds) {
        if (name == "bruteforce" &&
            (kind == QueryKind::FirstHitStream || kind == QueryKind::OccludedStream))
          continue;  // the oracle has no stream path
        benchmark::RegisterBenchmark(
            (std::string(kindName(kind)) + "/" + name + "/" + scene).c_str(), castRays, scene, name,
            kind)
            ->Unit(benchmark::kMicrosecond);
      }
    }
  }
}

}  // namespace
}  // namespace vistream

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  vistream::registerBenchmarks();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
