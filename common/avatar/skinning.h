// Skinned, animated models: glTF animations sampled at any time and linear
// blend skinning (up to four joints a vertex), as the glTF 2.0 specification
// defines them.
//
// Conventions: a SkinnedMesh is in model space (the file's coordinates, the
// scene's origin added back), Y up. Node matrices are global (parent times
// local, local = T * R * S). Clip times wrap around the clip's duration;
// times before a channel's first key hold its first value, after its last
// key its last value.
//
// Thread safety: everything here is immutable after construction or a free
// function of its arguments.
#pragma once

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>
#include <string>
#include <vector>

#include "common/scene/scene.h"

namespace vistream {

// One channel's value at time t: xyz for translation and scale, a unit
// quaternion (x, y, z, w) for rotation. Linear rotation is a spherical
// linear interpolation along the shorter arc; cubic-spline values are laid
// out (in-tangent, value, out-tangent) per key as glTF stores them, and a
// cubic-spline rotation is normalized.
glm::vec4 sampleChannel(const AnimationChannel& channel, float t);

// Every node's global matrix with `animation` (null: the rest pose) at clip
// time t (seconds, wrapped into [0, duration)).
std::vector<glm::mat4> globalNodeMatrices(const Scene& scene, const Animation* animation, float t);

// The skinning matrix of each joint of `skin`: its global matrix times its
// inverse bind matrix (identity where the skin has none).
std::vector<glm::mat4> jointMatrices(const Skin& skin, const std::vector<glm::mat4>& globals);

// A skinned object's triangles and their skin, ready to pose.
struct SkinnedMesh {
  std::string name;
  std::vector<glm::vec3> positions;  // bind pose, model space
  std::vector<glm::uvec3> triangles;
  std::vector<uint32_t> faceIds;     // per triangle, as in the source
  std::vector<glm::vec2> texcoords;  // per vertex, empty if none
  std::vector<uint32_t> materials;   // per triangle
  std::vector<glm::u16vec4> joints;  // per vertex, indices into the skin's joints
  std::vector<glm::vec4> weights;    // per vertex, normalized to sum 1
  int32_t skin = -1;

  // The first skinned object of `scene` (InputError if it has none, or a
  // joint index beyond its skin).
  static SkinnedMesh firstOf(const Scene& scene);

  // The mesh with vertices at the same position (and the same skin) merged
  // and each triangle split `times` times: into four at its edge midpoints,
  // or into three around its centroid. A new vertex's skin is the blend of
  // its edge's or triangle's corners' (the four largest weights kept,
  // renormalized). Either way triangle t's children are the next
  // split-factor triangles from split-factor x t, so fine triangle t descends
  // from coarse triangle t / factor^times. Texture coordinates and face IDs
  // are dropped: the result is for shadow computations (a finer test model,
  // the paper's "Hand" stand-in), not for display. Centroid splits make
  // slivers: three passes take the Fox to 7,778 vertices, near the Hand's
  // 8,636, where midpoints give 4,610 or 18,434.
  enum class Split { AtMidpoints = 4, AtCentroids = 3 };
  SkinnedMesh subdivided(int times, Split split = Split::AtMidpoints) const;
};

// Positions and unit normals (area-weighted from the triangles) of `mesh`
// posed by `joints` (jointMatrices of its skin).
struct PosedMesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;
};
void poseMesh(const SkinnedMesh& mesh, const std::vector<glm::mat4>& joints, PosedMesh& out);
// poseMesh with `animation` (of `scene`, the mesh's source) at clip time t;
// null: the rest pose.
void poseAt(const Scene& scene, const SkinnedMesh& mesh, const Animation* animation, float t,
            PosedMesh& out);

// Per-vertex normals of a triangle mesh: the area-weighted sum of its
// triangles' normals, normalized (up for a vertex with no area around it).
void vertexNormals(const std::vector<glm::vec3>& positions,
                   const std::vector<glm::uvec3>& triangles, std::vector<glm::vec3>& normals);

// The animation of `scene` called `name` (case-insensitive), or null.
const Animation* findAnimation(const Scene& scene, const std::string& name);

}  // namespace vistream
