#include "common/generate/path.h"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <deque>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>

#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "common/raycast/ray_query.h"
#include "common/world/static_world.h"

namespace vistream {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double uniform01(std::mt19937_64& rng) {
  return double(rng() >> 11) * 0x1.0p-53;
}

// Shortest 8-connected grid path (BFS with diagonal steps only where both
// side columns are walkable, so paths never cut a corner).
std::vector<glm::ivec2> gridPath(const FreeSpace& fs, glm::ivec2 from, glm::ivec2 to) {
  const int nx = fs.columnsX(), nz = fs.columnsZ();
  std::vector<int32_t> parent(size_t(nx) * size_t(nz), -1);
  auto idx = [nx](glm::ivec2 c) { return size_t(c.y) * size_t(nx) + size_t(c.x); };
  std::deque<glm::ivec2> queue{from};
  parent[idx(from)] = int32_t(idx(from));
  const int di[8] = {1, -1, 0, 0, 1, 1, -1, -1}, dk[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  while (!queue.empty()) {
    const glm::ivec2 c = queue.front();
    queue.pop_front();
    if (c == to) break;
    for (int d = 0; d < 8; ++d) {
      const glm::ivec2 n{c.x + di[d], c.y + dk[d]};
      if (!fs.walkable(n.x, n.y) || parent[idx(n)] >= 0) continue;
      if (std::abs(fs.floorHeight(n.x, n.y) - fs.floorHeight(c.x, c.y)) > fs.maxStep()) continue;
      if (d >= 4 && (!fs.walkable(c.x + di[d], c.y) || !fs.walkable(c.x, c.y + dk[d]))) continue;
      parent[idx(n)] = int32_t(idx(c));
      queue.push_back(n);
    }
  }
  std::vector<glm::ivec2> path;
  if (parent[idx(to)] < 0) return path;
  for (size_t c = idx(to);; c = size_t(parent[c])) {
    path.emplace_back(int(c % size_t(nx)), int(c / size_t(nx)));
    if (c == idx(from)) break;
  }
  std::reverse(path.begin(), path.end());
  return path;
}

// True if every column the segment passes over is walkable (sampled at a
// quarter of the column size, with the viewer radius already in the grid).
bool lineOfSight(const FreeSpace& fs, glm::vec2 a, glm::vec2 b) {
  const float len = glm::length(b - a);
  const int steps = std::max(1, int(std::ceil(len / (0.25f * fs.cellSize()))));
  float prevFloor = *fs.floorAt(a);
  for (int s = 1; s <= steps; ++s) {
    const auto f = fs.floorAt(a + (b - a) * (float(s) / float(steps)));
    if (!f || std::abs(*f - prevFloor) > fs.maxStep()) return false;
    prevFloor = *f;
  }
  return true;
}

// Columns within `metres` of a column along one axis, cut at the grid's size
// (so an absurd reach cannot overflow the window arithmetic).
int columnsWithin(const FreeSpace& fs, double metres) {
  const double cells = std::ceil(std::max(0.0, metres) / double(fs.cellSize()));
  return int(std::min(cells, double(std::max(fs.columnsX(), fs.columnsZ()))));
}

// Per column of one line of `n`, whether a set entry of `set` lies within
// r entries (a running count over the window [i - r, i + r]).
void dilateLine(const uint8_t* set, size_t stride, int n, int r, uint8_t* out, size_t outStride) {
  int count = 0;
  for (int i = 0; i < std::min(n, r); ++i) count += set[size_t(i) * stride];
  for (int i = 0; i < n; ++i) {
    if (i + r < n) count += set[size_t(i + r) * stride];
    out[size_t(i) * outStride] = count > 0 ? 1 : 0;
    if (i - r >= 0) count -= set[size_t(i - r) * stride];
  }
}

}  // namespace

void validatePathOptions(const PathOptions& o) {
  auto finite = [](double v) { return std::isfinite(v); };
  if (!(o.speed > 0.0) || !finite(o.speed))
    throwInputError("path speed must be a positive number, got {}", o.speed);
  if (!(o.fps > 0.0) || !finite(o.fps))
    throwInputError("path fps must be a positive number, got {}", o.fps);
  if (!(o.maxTurnDegPerS > 0.0) || !finite(o.maxTurnDegPerS))
    throwInputError("path turn rate must be a positive number of degrees a second, got {}",
                    o.maxTurnDegPerS);
  if (!(o.lookAhead >= 0.0) || !finite(o.lookAhead))
    throwInputError("path look-ahead must be a non-negative number of metres, got {}", o.lookAhead);
  if (!finite(o.eyeHeight))
    throwInputError("path eye height must be a finite number of metres, got {}", o.eyeHeight);
  if (!(o.goalRadius >= 0.0) || !finite(o.goalRadius))
    throwInputError("path goal radius must be a non-negative number of metres, got {}",
                    o.goalRadius);
  if (!(o.goalClearance >= 0.0) || !finite(o.goalClearance))
    throwInputError("path goal clearance must be a non-negative number of metres, got {}",
                    o.goalClearance);
}

std::vector<glm::ivec2> columnsNearObstacles(const FreeSpace& fs, double reach) {
  const int nx = fs.columnsX(), nz = fs.columnsZ();
  const int r = columnsWithin(fs, reach);
  std::vector<uint8_t> blocked(size_t(nx) * size_t(nz)), alongX(blocked.size()),
      near(blocked.size());
  for (int k = 0; k < nz; ++k)
    for (int i = 0; i < nx; ++i) blocked[size_t(k) * size_t(nx) + size_t(i)] = !fs.walkable(i, k);
  for (int k = 0; k < nz; ++k) {
    const size_t row = size_t(k) * size_t(nx);
    dilateLine(blocked.data() + row, 1, nx, r, alongX.data() + row, 1);
  }
  for (int i = 0; i < nx; ++i)
    dilateLine(alongX.data() + i, size_t(nx), nz, r, near.data() + i, size_t(nx));
  std::vector<glm::ivec2> out;
  for (const glm::ivec2& c : fs.walkableColumns())
    if (near[size_t(c.y) * size_t(nx) + size_t(c.x)]) out.push_back(c);
  return out;
}

std::vector<float> obstacleDensity(const FreeSpace& fs, double radius) {
  const int nx = fs.columnsX(), nz = fs.columnsZ();
  const int r = columnsWithin(fs, radius);
  // Summed-area table of the unwalkable columns.
  const size_t stride = size_t(nx) + 1;
  std::vector<uint32_t> sum(stride * (size_t(nz) + 1), 0);
  for (int k = 0; k < nz; ++k)
    for (int i = 0; i < nx; ++i)
      sum[size_t(k + 1) * stride + size_t(i + 1)] =
          (fs.walkable(i, k) ? 0u : 1u) + sum[size_t(k) * stride + size_t(i + 1)] +
          sum[size_t(k + 1) * stride + size_t(i)] - sum[size_t(k) * stride + size_t(i)];
  std::vector<float> out;
  out.reserve(fs.walkableCount());
  for (const glm::ivec2& c : fs.walkableColumns()) {
    const int i0 = std::max(0, c.x - r), i1 = std::min(nx, c.x + r + 1);
    const int k0 = std::max(0, c.y - r), k1 = std::min(nz, c.y + r + 1);
    const uint32_t blocked =
        sum[size_t(k1) * stride + size_t(i1)] - sum[size_t(k0) * stride + size_t(i1)] -
        sum[size_t(k1) * stride + size_t(i0)] + sum[size_t(k0) * stride + size_t(i0)];
    out.push_back(float(blocked) / float((i1 - i0) * (k1 - k0)));
  }
  return out;
}

std::vector<glm::ivec2> goalColumns(const FreeSpace& fs, const PathOptions& options) {
  if (options.goalRadius > 0.0 && fs.walkableCount() > 0) {
    // The denser half by obstacles around, less the columns against one.
    const std::vector<glm::ivec2> all = fs.walkableColumns(),
                                  tooNear = columnsNearObstacles(fs, options.goalClearance);
    const std::vector<float> density = obstacleDensity(fs, options.goalRadius);
    std::vector<float> sorted = density;
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2),
                     sorted.end());
    const float median = sorted[sorted.size() / 2];
    std::vector<glm::ivec2> columns;
    size_t near = 0;  // walks tooNear, which is in the same order as all
    for (size_t c = 0; c < all.size(); ++c) {
      const bool against = near < tooNear.size() && tooNear[near] == all[c];
      near += against;
      if (!against && density[c] >= median && density[c] > 0.0f) columns.push_back(all[c]);
    }
    // One column is no walk: a goal must differ from where the walk stands.
    if (columns.size() >= 2) return columns;
  }
  return fs.walkableColumns();
}

std::vector<PathSample> generatePath(const Scene& scene, const FreeSpace& fs,
                                     const PathOptions& options) {
  validatePathOptions(options);
  return generatePath(scene, fs, goalColumns(fs, options), options);
}

std::vector<PathSample> generatePath(const Scene& scene, const FreeSpace& fs,
                                     const std::vector<glm::ivec2>& goals,
                                     const PathOptions& options) {
  if (fs.walkableCount() == 0)
    throwInputError("scene '{}' has no free space to walk through: {}", scene.name,
                    fs.emptyReason());
  validatePathOptions(options);
  for (const glm::ivec2& g : goals)
    if (!fs.walkable(g.x, g.y))
      throwInputError("path goal column ({}, {}) is not walkable", g.x, g.y);
  const std::vector<glm::ivec2>& columns = goals.empty() ? fs.walkableColumns() : goals;
  std::mt19937_64 rng(options.seed);
  auto randomColumn = [&] {
    return columns[size_t(uniform01(rng) * double(columns.size())) % columns.size()];
  };

  const double step = kWalkingSpeed * options.speed / options.fps;  // metres per frame
  std::vector<PathSample> out;
  out.reserve(options.frames);
  glm::ivec2 at = randomColumn();
  glm::dvec2 pos = glm::dvec2(fs.columnCentre(at.x, at.y));
  double yaw = 0.0;  // set towards the first waypoint
  // The polyline walked: legs to random goals, each a smoothed shortest
  // grid path, the next planned before the walk reaches the end of the last
  // (so the gaze, looking ahead, turns into the next leg instead of facing
  // whatever lies beyond a goal).
  std::vector<glm::dvec2> waypoints{pos};
  size_t nextWaypoint = 1;
  int failures = 0;
  auto planLeg = [&] {
    const glm::ivec2 goal = randomColumn();
    const std::vector<glm::ivec2> grid =
        goal == at ? std::vector<glm::ivec2>{} : gridPath(fs, at, goal);
    if (grid.size() < 2) {
      if (++failures > 1000)
        throwInputError("scene '{}': no room to walk in its free space", scene.name);
      return;
    }
    size_t anchor = 0;
    while (anchor + 1 < grid.size()) {
      size_t far = anchor + 1;
      const glm::vec2 a = fs.columnCentre(grid[anchor].x, grid[anchor].y);
      while (far + 1 < grid.size() &&
             lineOfSight(fs, a, fs.columnCentre(grid[far + 1].x, grid[far + 1].y)))
        ++far;
      waypoints.push_back(glm::dvec2(fs.columnCentre(grid[far].x, grid[far].y)));
      anchor = far;
    }
    at = goal;
    failures = 0;
  };
  // Path length from pos to the last waypoint, up to `enough`.
  auto pathLeft = [&](double enough) {
    double length = 0.0;
    glm::dvec2 from = pos;
    for (size_t w = nextWaypoint; w < waypoints.size() && length < enough; ++w) {
      length += glm::length(waypoints[w] - from);
      from = waypoints[w];
    }
    return length;
  };

  while (out.size() < options.frames) {
    const double needed = step + options.lookAhead;
    while (pathLeft(needed) < needed) planLeg();
    if (out.empty()) {                          // the walk starts looking where it goes
      const glm::dvec2 d = waypoints[1] - pos;  // the first leg: at least one column long
      yaw = std::atan2(-d.x, -d.y) / kDeg;
    }
    // Advance one frame along the polyline.
    double remaining = step;
    while (remaining > 0.0 && nextWaypoint < waypoints.size()) {
      const glm::dvec2 d = waypoints[nextWaypoint] - pos;
      const double len = glm::length(d);
      if (len <= remaining) {
        pos = waypoints[nextWaypoint++];
        remaining -= len;
      } else {
        pos += d * (remaining / len);
        remaining = 0.0;
      }
    }
    // The gaze turns at a bounded rate towards the point lookAhead metres
    // further along the path, so it turns into a corner before reaching it
    // instead of facing the wall beside it.
    if (nextWaypoint < waypoints.size()) {
      glm::dvec2 ahead = pos;
      double left = options.lookAhead;
      for (size_t w = nextWaypoint; w < waypoints.size() && left > 0.0; ++w) {
        const glm::dvec2 leg = waypoints[w] - ahead;
        const double len = glm::length(leg);
        ahead = len <= left ? waypoints[w] : ahead + leg * (left / len);
        left -= len;
      }
      const glm::dvec2 d = ahead - pos;
      if (glm::length(d) > 1e-9) {
        const double target = std::atan2(-d.x, -d.y) / kDeg;
        double delta = std::remainder(target - yaw, 360.0);
        const double maxTurn = options.maxTurnDegPerS / options.fps;
        yaw += std::clamp(delta, -maxTurn, maxTurn);
        yaw = std::remainder(yaw, 360.0);
      }
    }
    const auto floor = fs.floorAt(glm::vec2(pos));
    const glm::ivec2 c = fs.columnOf(glm::vec2(pos));
    const double y = floor ? *floor
                           : fs.floorHeight(std::clamp(c.x, 0, fs.columnsX() - 1),
                                            std::clamp(c.y, 0, fs.columnsZ() - 1));
    PathSample s;
    s.t = double(out.size()) / options.fps;
    s.position = scene.toFile(glm::vec3(float(pos.x), float(y + options.eyeHeight), float(pos.y)));
    s.yawDeg = yaw;
    s.pitchDeg = 0.0;
    out.push_back(s);
  }
  return out;
}

std::vector<PathSample> readPath(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throwInputError("{}: cannot open path file", path.string());
  std::string line;
  size_t lineNo = 0;
  std::vector<PathSample> out;
  bool header = false;
  while (std::getline(in, line)) {
    ++lineNo;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    if (!header) {
      std::string compact;
      for (char ch : line)
        if (ch != ' ' && ch != '\t') compact += ch;
      if (compact != "t,x,y,z,yaw_deg,pitch_deg")
        throwInputError("{}:{}: expected the header 't,x,y,z,yaw_deg,pitch_deg', got '{}'",
                        path.string(), lineNo, line);
      header = true;
      continue;
    }
    double v[6];
    size_t field = 0, pos = 0;
    while (field < 6) {
      size_t comma = line.find(',', pos);
      std::string_view tok = std::string_view(line).substr(
          pos, comma == std::string::npos ? std::string::npos : comma - pos);
      while (!tok.empty() && (tok.front() == ' ' || tok.front() == '\t')) tok.remove_prefix(1);
      while (!tok.empty() && (tok.back() == ' ' || tok.back() == '\t')) tok.remove_suffix(1);
      const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v[field]);
      if (ec != std::errc() || ptr != tok.data() + tok.size() || !std::isfinite(v[field]))
        throwInputError("{}:{}: field {} ('{}') is not a finite number", path.string(), lineNo,
                        field + 1, tok);
      ++field;
      if (comma == std::string::npos) break;
      pos = comma + 1;
      if (field == 6) throwInputError("{}:{}: more than 6 fields", path.string(), lineNo);
    }
    if (field != 6)
      throwInputError("{}:{}: {} fields, expected 6 (t,x,y,z,yaw_deg,pitch_deg)", path.string(),
                      lineNo, field);
    if (!out.empty() && v[0] < out.back().t)
      throwInputError("{}:{}: t goes backwards ({} after {})", path.string(), lineNo, v[0],
                      out.back().t);
    if (std::abs(v[5]) > 90.0)
      throwInputError("{}:{}: pitch {} is outside [-90, 90] (the viewer is upright)", path.string(),
                      lineNo, v[5]);
    out.push_back(PathSample{v[0], {v[1], v[2], v[3]}, v[4], v[5]});
  }
  if (!header) throwInputError("{}: empty path file (no header)", path.string());
  if (out.empty()) throwInputError("{}: path has no samples", path.string());
  return out;
}

void writePath(const std::vector<PathSample>& samples, const std::filesystem::path& path) {
  fmt::memory_buffer buf;
  fmt::format_to(std::back_inserter(buf), "t,x,y,z,yaw_deg,pitch_deg\n");
  for (const PathSample& s : samples)
    fmt::format_to(std::back_inserter(buf), "{:.6f},{:.6f},{:.6f},{:.6f},{:.4f},{:.4f}\n", s.t,
                   s.position.x, s.position.y, s.position.z, s.yawDeg, s.pitchDeg);
  writeFileAtomically(path, std::string_view(buf.data(), buf.size()));
}

std::vector<PathSample> generatePath(const Scene& scene, const PathOptions& options) {
  StaticWorldOptions worldOptions;
  worldOptions.ground = options.ground;
  return generatePath(scene, buildStaticWorld(scene, worldOptions).freeSpace, options);
}

}  // namespace vistream
