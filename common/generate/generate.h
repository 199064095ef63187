// Procedural scenes, deterministic by seed (same seed, same bytes on every
// machine: only integer-seeded std::mt19937_64 and our own distributions).
//
// Scene types:
//  - "city1" (dense) and "city2" (sparse): the cities of Cohen-Or and
//    Zadicario 1998 (Section 5): 2,128 buildings on a plane, simple closed
//    boxes, about 25% built of three stacked boxes of random height, plus one
//    ground tile per building lot; about 21,000 polygons (the paper's 21,280).
//  - "bigcity": at least 2 million triangles over about 4 km^2, buildings
//    with detailed facades (as in Wimmer's thesis), streets free of geometry.
//  - "interior": one building floor of rooms, corridors and doors with
//    furniture, sized like scene I of Bittner and Havran 2001.
//  - "interior2": the same floor with every wall cut into boxes at most 2 m
//    long (the patches of a radiosity solution), sized like scene II of
//    Bittner and Havran 2001 (1,605 kD-tree nodes; 32 occluders needed).
//  - "terrain": open land with hills and distant mountains under open sky.
//
// Generators build polygon objects (faces as vertex loops, the way an OBJ
// file stores them); toScene() triangulates them into a Scene with the same
// face IDs that loading the written OBJ would give.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "common/scene/scene.h"

namespace vistream {

struct PolygonObject {
  std::string name;
  std::vector<glm::dvec3> vertices;  // file coordinates, metres
  std::vector<std::vector<uint32_t>>
      faces;              // each a loop of vertex indices (CCW seen from outside)
  uint32_t material = 0;  // index into PolygonScene::materials
  bool dynamic = false;
};

struct PolygonScene {
  std::string name;
  std::vector<Material> materials;
  std::vector<PolygonObject> objects;

  size_t faceCount() const;
};

// The scene types generate() accepts, in the order `--help` lists them.
const std::vector<std::string>& sceneTypes();

// Generates a scene by type name (see above). Throws InputError on an unknown type.
PolygonScene generate(const std::string& type, uint64_t seed = 1);

// Individual generators.
PolygonScene generateCity(bool dense, uint64_t seed);
PolygonScene generateBigCity(uint64_t seed);
// wallPatch > 0 cuts every wall into boxes at most that long, each its own
// object ("interior2" uses this).
PolygonScene generateInterior(uint64_t seed, double wallPatch = 0.0);
PolygonScene generateTerrain(uint64_t seed);

// The built-in avatar "walker": a skinned figure of boxes (torso, head, two
// legs bending at the knee, two arms; 1.75 m tall, facing +Z) on nine
// joints, with the clips Survey (3 s, head and torso turn), Walk (1 s) and
// Run (0.6 s). A skinned test model besides the Fox (openScene("walker")).
Scene generateWalker();

// Triangulated scene with face IDs in object-then-face order (the OBJ order).
Scene toScene(const PolygonScene& polygons);

// Writes an OBJ (+ .mtl beside it) with `o NAME` per object and one `f` line
// per polygon face, so that loading it gives the same face IDs as toScene().
// Written to a temporary file and renamed: no torn file on a crash.
void writeObj(const PolygonScene& polygons, const std::filesystem::path& path);

}  // namespace vistream
