// Walkthrough paths: generation through a scene's free space, and the path
// file format.
//
// Path file: CSV with the header `t,x,y,z,yaw_deg,pitch_deg`, one row per
// frame; t in seconds (non-decreasing), x,y,z the eye position in the scene
// file's coordinates (metres, Y up). yaw 0 looks along -Z, positive yaw turns
// left (towards -X, counter-clockwise seen from above); positive pitch looks
// up (common/core/view.h: viewDirection).
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <vector>

#include "common/core/view.h"
#include "common/scene/scene.h"
#include "common/world/free_space.h"
#include "common/world/static_world.h"

namespace vistream {

struct PathSample {
  double t = 0.0;
  glm::dvec3 position{0.0};  // file coordinates
  double yawDeg = 0.0;
  double pitchDeg = 0.0;
};

struct PathOptions {
  double speed = 1.0;  // relative: 1.0 = walking, 1.4 m/s
  size_t frames = 300;
  double fps = 30.0;
  double eyeHeight = 1.7;         // metres above the floor under the viewer
  double maxTurnDegPerS = 120.0;  // how fast the gaze follows the walking direction
  double lookAhead = 4.0;         // metres along the path to the point the gaze turns towards
  uint64_t seed = 1;
  // Where the walk's start and goals are drawn: the walkable columns whose
  // surroundings (the square of half-side goalRadius metres) hold the most
  // obstacles, the denser half of them (the streets among a city's
  // buildings, not the open ground around it), leaving out those within
  // goalClearance metres of an obstacle (a walk does not start with its nose
  // at a wall). When that leaves none, or with goalRadius 0: any walkable
  // column.
  double goalRadius = 20.0;
  double goalClearance = 2.0;
  // The ground decision when generatePath builds the free space itself
  // (the overload without a FreeSpace); see static_world.h.
  GroundChoice ground;
};

inline constexpr double kWalkingSpeed = 1.4;  // m/s at relative speed 1.0

// Generates an upright path through the free space: random goals (among
// obstacles: PathOptions::goalRadius) reached by shortest grid paths,
// smoothed by line-of-sight shortcuts, walked at the given speed. Throws InputError if the scene
// has no free space, saying why (FreeSpace::emptyReason).
std::vector<PathSample> generatePath(const Scene& scene, const FreeSpace& freeSpace,
                                     const PathOptions& options);
// The same with the goal columns given (goalColumns computed once for many
// walks through one free space, as the load tester does); an empty list
// means any walkable column. Throws InputError on a goal that is not walkable.
std::vector<PathSample> generatePath(const Scene& scene, const FreeSpace& freeSpace,
                                     const std::vector<glm::ivec2>& goals,
                                     const PathOptions& options);
// The same, building the scene's static world first (buildStaticWorld with
// options.ground; for callers that need one path and no free space of their own).
std::vector<PathSample> generatePath(const Scene& scene, const PathOptions& options);

// Throws InputError naming the first option out of range: speed, fps and
// turn rate must be positive, look-ahead, goal radius and clearance
// non-negative, every figure finite.
void validatePathOptions(const PathOptions& options);
// Where walks with these options start and aim (PathOptions::goalRadius):
// at least two columns, or every walkable column.
std::vector<glm::ivec2> goalColumns(const FreeSpace& freeSpace, const PathOptions& options);

// The walkable columns within `reach` metres (along each axis) of a column
// inside the grid that is not walkable: a building, a wall, a step.
std::vector<glm::ivec2> columnsNearObstacles(const FreeSpace& freeSpace, double reach);
// Per walkable column (walkableColumns() order), the share of the columns
// within `radius` metres along each axis (the square around it, cut at the
// grid's edge) that are not walkable.
std::vector<float> obstacleDensity(const FreeSpace& freeSpace, double radius);

// Reads a path file; throws InputError naming the file and line on a bad
// header, a non-numeric or non-finite field, a missing column or t going backwards.
std::vector<PathSample> readPath(const std::filesystem::path& path);
// Writes atomically (temporary file, then rename).
void writePath(const std::vector<PathSample>& samples, const std::filesystem::path& path);

}  // namespace vistream
