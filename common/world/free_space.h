// Free space of a scene: where an upright viewer can stand.
//
// A regular grid over the scene's XZ extent. For each column a vertical ray
// collects every surface; a column is walkable at the lowest horizontal
// surface (|n.y| above `upwardNormalY`; either winding, except that a face
// of a closed, consistently oriented solid counts only with its outside up)
// with at least `headroom` metres free above it whose point 1 m above it
// lies outside every solid (Solids::inside, which uses no winding); a floor inside a
// solid is skipped and the next one up tried. A solid resting on a floor at
// the same height leaves that floor no headroom. Columns closer than
// `viewerRadius` to an unwalkable column are removed, then only the largest
// 4-connected set whose neighbouring floors differ by at most the step
// height is kept (the street network of a city, the corridors and rooms of
// a building joined by doors, the gentle part of a terrain). Roofs and
// mountain flanks fall out by the step and connectivity rules.
//
// An assumed ground plane (FreeSpaceOptions::groundY, decided by
// static_world.h for scenes without a ground surface) is an infinite
// horizontal floor under every column.
//
// Limitation: one walkable level per column (the lowest); multi-storey
// walkthroughs use the ground floor.
//
// Used by path generation, the PVS bake (cells over free space) and the
// effects decision (is there open sky above the free space?). Build it
// through buildStaticWorld (static_world.h), which supplies the solids and
// the ground plane.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "common/raycast/ray_query.h"
#include "common/world/solids.h"

namespace vistream {

struct FreeSpaceOptions {
  float minCellSize = 0.1f;  // metres
  size_t maxColumns =
      1'000'000;              // grid resolution cap: cell = max(minCellSize, sqrt(area/maxColumns))
  float headroom = 2.0f;      // metres free above the floor
  float viewerRadius = 0.3f;  // metres kept from obstacles
  float upwardNormalY = 0.5f;  // |n.y| / |n| above which a surface counts as floor
  // An assumed ground plane at this local height (metres): an infinite floor
  // under every column. Empty: only the scene's own surfaces.
  std::optional<float> groundY;
};

// How the grid's columns fared, in the order the rules apply.
struct FreeSpaceStats {
  size_t columns = 0;
  size_t noFloor = 0;       // no horizontal surface with headroom above it
  size_t insideSolid = 0;   // every floor with headroom had its point 1 m above inside a solid
  size_t floors = 0;        // columns with a floor to stand on
  size_t nearObstacle = 0;  // floors within the viewer radius of an obstacle or a step
  size_t disconnected = 0;  // floors outside the largest connected set
  SolidCensus solids;       // the components the inside test used
};

class FreeSpace {
 public:
  // `bounds` is the scene's local bounding box; `solids` and `rays` cover the
  // same triangles (normally the scene's static geometry).
  static FreeSpace build(const RayQuery& rays, const Solids& solids, const Box3f& bounds,
                         const FreeSpaceOptions& options = {});

  int columnsX() const { return nx_; }
  int columnsZ() const { return nz_; }
  float cellSize() const { return cell_; }
  size_t walkableCount() const { return walkableCount_; }

  bool walkable(int i, int k) const {
    return i >= 0 && k >= 0 && i < nx_ && k < nz_ && walkable_[index(i, k)] != 0;
  }
  float floorHeight(int i, int k) const { return floor_[index(i, k)]; }
  glm::vec2 columnCentre(int i, int k) const {
    return {origin_.x + (float(i) + 0.5f) * cell_, origin_.y + (float(k) + 0.5f) * cell_};
  }
  glm::ivec2 columnOf(const glm::vec2& xz) const;
  // Floor height under a local XZ point if its column is walkable.
  std::optional<float> floorAt(const glm::vec2& xz) const;
  std::vector<glm::ivec2> walkableColumns() const;
  float maxStep() const { return maxStep_; }
  const FreeSpaceStats& stats() const { return stats_; }
  // Why there is no walkable column (one sentence naming the rule that
  // removed them and, with solids, how many faces are wound inconsistently);
  // empty when there is free space.
  std::string emptyReason() const;

 private:
  size_t index(int i, int k) const { return size_t(k) * size_t(nx_) + size_t(i); }

  int nx_ = 0, nz_ = 0;
  float cell_ = 1.0f;
  float maxStep_ = 0.5f;
  glm::vec2 origin_{0.0f};  // local XZ of the grid's lower corner
  std::vector<uint8_t> walkable_;
  std::vector<float> floor_;
  size_t walkableCount_ = 0;
  float headroom_ = 2.0f, viewerRadius_ = 0.3f;
  FreeSpaceStats stats_;
};

}  // namespace vistream
