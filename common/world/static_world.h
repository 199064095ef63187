// One recipe for "a static world": the scene's static triangles, an Embree
// ray query over them, their solids, the ground decision and the free space.
// Every tool and server that needs free space builds it here, so they all
// walk the same streets.
//
// Ground: a city model of buildings only (LoD2 exports such as
// ../shared/data/delfshaven.obj) has no surface between its buildings, so
// the only floors with headroom are roofs. With GroundMode::Auto, when a
// share of at least kBareFootprintForGround of the scene's XZ footprint has
// no surface under it at all, a ground plane is assumed at the lowest base of
// its static objects (the lowest point of any of them). None never assumes
// one; Fixed puts it at a given height in file coordinates.
//
// Frames: everything in the StaticWorld is in the scene's local frame
// except GroundChoice::fileY (file coordinates, as typed on a command line).
// Ownership: `rays` refers to `*triangles`; a StaticWorld is move-only and
// keeps them together (move it whole, or the triangles with the rays). Thread safety: immutable
// after buildStaticWorld; queries may run from any thread.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "common/world/free_space.h"
#include "common/world/solids.h"

namespace vistream {

enum class GroundMode : uint8_t { Auto, None, Fixed };

struct GroundChoice {
  GroundMode mode = GroundMode::Auto;
  double fileY = 0.0;  // with Fixed: height of the plane in file coordinates (metres)
};

// Parses "auto", "none" or a finite number (metres, file Y); nothing for
// any other text (command lines check with this at parse time).
std::optional<GroundChoice> parseGroundChoice(const std::string& text);

inline constexpr double kBareFootprintForGround = 0.10;

// What was decided about the ground, and why (one line for logs and `info`).
struct GroundPlane {
  std::optional<float> y;      // local height of the assumed plane; empty: none assumed
  double bareFootprint = 0.0;  // share of sampled XZ columns with no surface under them
  std::string why;
};

// How much of the recipe to build; each part includes the ones before it.
enum class StaticWorldParts : uint8_t {
  Rays,       // triangles and the ray query
  Ground,     // + the ground decision
  Solids,     // + solids
  FreeSpace,  // + free space
};

struct StaticWorldOptions {
  GroundChoice ground;
  FreeSpaceOptions freeSpace;  // its groundY is overwritten by the ground decision
  StaticWorldParts parts = StaticWorldParts::FreeSpace;
};

struct StaticWorld {
  // Static objects only. On the heap: `rays` keeps a reference to it, which
  // stays valid when the StaticWorld moves.
  std::unique_ptr<const FlatTriangles> triangles;
  std::unique_ptr<RayQuery> rays;
  Solids solids;        // empty unless parts >= Solids
  GroundPlane ground;   // no plane unless parts >= Ground
  FreeSpace freeSpace;  // empty unless parts == FreeSpace
};

// Builds the whole recipe and logs the ground decision (info when a plane is
// assumed). Does not throw on any scene; an empty free space is reported by
// FreeSpace::emptyReason(), not here.
StaticWorld buildStaticWorld(const Scene& scene, const StaticWorldOptions& options = {});

// The ground decision alone (used by buildStaticWorld; exposed for tests).
GroundPlane decideGround(const Scene& scene, const RayQuery& rays, const GroundChoice& choice);

}  // namespace vistream
