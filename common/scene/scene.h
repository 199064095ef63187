// The scene model every part of vistream speaks.
//
// Conventions: Y up, metres, right-handed. A scene is a set of named objects,
// each an indexed triangle mesh, flagged static or dynamic. Every triangle
// keeps the global face ID of the source face it came from: the 0-based order
// of faces in the source file (OBJ: `f` lines, whatever their vertex count, so
// a quad's two triangles share one ID; glTF: triangle order by mesh primitive
// in node traversal order). Every output (PVS, streams, ground truth) speaks
// in these IDs.
//
// Precision: positions are stored as float relative to Scene::origin (double,
// in file coordinates), so a city 50 km from the world origin keeps
// sub-millimetre precision. Use toFile()/toLocal() at the boundary; anything
// printed for a person or a machine is in file coordinates.
//
// Thread safety: a Scene is immutable after loading and may be shared by any
// number of readers.
#pragma once

#include <cstdint>
#include <filesystem>
#include <glm/glm.hpp>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/core/box.h"

namespace vistream {

struct Material {
  std::string name;
  glm::vec3 diffuse{0.8f, 0.8f, 0.8f};          // linear RGB, what every renderer shades with
  glm::vec4 baseColor{0.8f, 0.8f, 0.8f, 1.0f};  // glTF baseColorFactor (RGBA)
  std::string baseColorTexture;                 // file path or glTF image name; empty if none
  // The encoded bytes (PNG, JPEG) of a base-colour image the scene file holds
  // itself (a glb buffer view, a data URI); null when baseColorTexture names
  // a file. Shared: copies of a scene do not copy images.
  std::shared_ptr<const std::vector<uint8_t>> baseColorImage;
  // The loader's stand-in for faces the source gave no material: the lighting
  // colours them by orientation instead (common/light/lighting.h).
  bool unassigned = false;

  static Material named(std::string name) {
    Material m;
    m.name = std::move(name);
    return m;
  }
  // The stand-in for faces without a material in their source.
  static Material unassignedDefault() {
    Material m = named("default");
    m.unassigned = true;
    return m;
  }
  // A plain diffuse material (base colour the same, opaque).
  static Material diffuseColour(std::string name, glm::vec3 diffuse) {
    Material m = named(std::move(name));
    m.diffuse = diffuse;
    m.baseColor = glm::vec4(diffuse, 1.0f);
    return m;
  }
};

struct TriangleMesh {
  std::vector<glm::vec3> positions;   // local frame (relative to Scene::origin), metres
  std::vector<glm::uvec3> triangles;  // indices into positions
  std::vector<uint32_t> faceIds;      // per triangle: global source face ID
  std::vector<uint32_t> materials;    // per triangle: index into Scene::materials
  std::vector<glm::vec2> texcoords;   // per vertex, empty if the source had none
  // Skinning (glTF): per vertex four joint indices and weights; empty if not skinned.
  std::vector<glm::u16vec4> joints;
  std::vector<glm::vec4> weights;

  size_t triangleCount() const { return triangles.size(); }
};

struct Object {
  std::string name;
  TriangleMesh mesh;
  bool dynamic = false;
  int32_t skin = -1;  // index into Scene::skins, -1 if none
  Box3f bounds;       // local frame
};

// glTF skin: joints are node indices into Scene::nodes.
struct Skin {
  std::string name;
  std::vector<int32_t> joints;
  std::vector<glm::mat4> inverseBindMatrices;
};

// glTF node hierarchy, kept so that skins and animations can be evaluated.
struct Node {
  std::string name;
  int32_t parent = -1;
  glm::vec3 translation{0.0f};
  glm::vec4 rotation{0.0f, 0.0f, 0.0f, 1.0f};  // quaternion x, y, z, w
  glm::vec3 scale{1.0f};
};

struct AnimationChannel {
  int32_t node = -1;
  enum class Path : uint8_t { Translation, Rotation, Scale } path = Path::Translation;
  enum class Interpolation : uint8_t {
    Linear,
    Step,
    CubicSpline
  } interpolation = Interpolation::Linear;
  std::vector<float> times;
  std::vector<glm::vec4> values;  // xyz for translation/scale, xyzw for rotation
};

struct Animation {
  std::string name;
  std::vector<AnimationChannel> channels;
  float duration = 0.0f;  // seconds
};

// Sky as declared by a manifest. Auto means: derive it from the geometry.
enum class SkyMode : uint8_t { Auto, Open, None };

struct Environment {
  std::filesystem::path hdrImage;  // equirectangular Radiance HDR, empty if none
  SkyMode sky = SkyMode::Auto;
  glm::vec3 skyColor{0.55f, 0.7f, 0.9f};
  // The sun of the baked lighting (common/light/lighting.h): towards the sun,
  // unit, local frame; intensity 0 means no sun.
  glm::vec3 sunDirection = glm::normalize(glm::vec3(0.35f, 0.85f, 0.4f));
  float sunIntensity = 0.5f;
  float hazeDistance = 800.0f;     // metres at which haze hides 63% of a colour; 0: no haze
  float nearFieldRadius = 150.0f;  // metres; the client's near-field distance d
};

// What loading found wrong but survivable. Degenerate triangles (zero area or
// repeated vertices) stay in the scene as visible geometry but are never used
// as occluders.
struct SceneDiagnostics {
  uint64_t degenerateTriangles = 0;
  uint64_t repeatedVertexTriangles = 0;
  uint64_t zeroAreaTriangles = 0;
  std::vector<std::string> warnings;
};

struct Scene {
  std::string name;
  std::vector<std::filesystem::path> sources;  // files the scene was read from, in face-ID order
  glm::dvec3 origin{0.0};                      // local origin, file coordinates
  std::vector<Object> objects;
  std::vector<Material> materials;  // never empty after loading
  std::vector<Node> nodes;
  std::vector<Skin> skins;
  std::vector<Animation> animations;
  Environment environment;
  SceneDiagnostics diagnostics;
  uint32_t faceCount = 0;  // number of source faces; face IDs are 0..faceCount-1

  glm::dvec3 toFile(const glm::vec3& local) const { return origin + glm::dvec3(local); }
  glm::vec3 toLocal(const glm::dvec3& file) const { return glm::vec3(file - origin); }

  size_t triangleCount() const;
  Box3f bounds() const;  // local frame, over all objects
  Box3d fileBounds() const;
  size_t dynamicObjectCount() const;
};

// All triangles of a scene in one table, for spatial structures and ray
// queries. Triangle i of the table is (positions[3i], positions[3i+1],
// positions[3i+2]) in the local frame.
struct FlatTriangles {
  std::vector<glm::vec3> positions;  // 3 per triangle
  std::vector<uint32_t> faceIds;     // per triangle
  std::vector<uint32_t> objectIds;   // per triangle
  std::vector<uint8_t> degenerate;   // per triangle: 1 if zero area or repeated vertices

  size_t size() const { return faceIds.size(); }
  glm::vec3 vertex(size_t tri, int k) const { return positions[3 * tri + size_t(k)]; }
  Box3f triangleBounds(size_t tri) const;
};

// Flattens the scene. With staticOnly, dynamic objects are left out.
FlatTriangles flattenScene(const Scene& scene, bool staticOnly = false);
// Flattens one indexed mesh (a posed avatar, say): triangle t becomes face t
// of object 0, degenerate as isDegenerateTriangle says.
FlatTriangles flattenMesh(const std::vector<glm::vec3>& positions,
                          const std::vector<glm::uvec3>& triangles);

// True if the triangle has zero area (relative to its size) or repeats a vertex.
bool isDegenerateTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c);

// Recomputes object bounds, diagnostics and faceCount after the objects were filled.
void finalizeScene(Scene& scene);

}  // namespace vistream
