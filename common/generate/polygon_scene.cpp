// Polygon scenes: dispatch by type name, triangulation into a Scene, OBJ output.
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <system_error>
#include <utility>

#include "common/core/atomic_file.h"
#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/scene/triangulate.h"

namespace vistream {
namespace {
// Wall patch length of "interior2", tuned so that its kD-tree over objects
// has about the 1,605 nodes of scene II in Bittner and Havran 2001.
constexpr double kInterior2WallPatch = 2.0;
}  // namespace

size_t PolygonScene::faceCount() const {
  size_t n = 0;
  for (const PolygonObject& o : objects) n += o.faces.size();
  return n;
}

const std::vector<std::string>& sceneTypes() {
  static const std::vector<std::string> types{"city1",    "city2",     "bigcity",
                                              "interior", "interior2", "terrain"};
  return types;
}

PolygonScene generate(const std::string& type, uint64_t seed) {
  PolygonScene scene;
  if (type == "city1") {
    scene = generateCity(true, seed);
  } else if (type == "city2") {
    scene = generateCity(false, seed);
  } else if (type == "bigcity") {
    scene = generateBigCity(seed);
  } else if (type == "interior") {
    scene = generateInterior(seed);
  } else if (type == "interior2") {
    scene = generateInterior(seed, kInterior2WallPatch);
  } else if (type == "terrain") {
    scene = generateTerrain(seed);
  } else {
    throwInputError("unknown scene type '{}' (expected one of: {})", type,
                    fmt::join(sceneTypes(), ", "));
  }
  scene.name = type;
  return scene;
}

Scene toScene(const PolygonScene& polygons) {
  Scene scene;
  scene.name = polygons.name;
  scene.materials = polygons.materials;

  // The local origin is the centre of the file-coordinate bounds, so float
  // positions keep their precision however far the scene is from (0, 0, 0).
  Box3d bounds;
  for (const PolygonObject& o : polygons.objects)
    for (const glm::dvec3& v : o.vertices) bounds.extend(v);
  scene.origin = bounds.empty() ? glm::dvec3(0.0) : bounds.center();

  // Face IDs in object-then-face order: each object starts where the previous ended.
  std::vector<uint32_t> firstFace(polygons.objects.size() + 1, 0);
  for (size_t i = 0; i < polygons.objects.size(); ++i)
    firstFace[i + 1] = firstFace[i] + uint32_t(polygons.objects[i].faces.size());

  scene.objects.resize(polygons.objects.size());
  tbb::parallel_for(size_t(0), polygons.objects.size(), [&](size_t oi) {
    const PolygonObject& source = polygons.objects[oi];
    Object& object = scene.objects[oi];
    object.name = source.name;
    object.dynamic = source.dynamic;
    TriangleMesh& mesh = object.mesh;
    mesh.positions.reserve(source.vertices.size());
    for (const glm::dvec3& v : source.vertices)
      mesh.positions.push_back(glm::vec3(v - scene.origin));

    std::vector<glm::dvec3> loop;
    std::vector<glm::uvec3> local;
    for (size_t f = 0; f < source.faces.size(); ++f) {
      const std::vector<uint32_t>& face = source.faces[f];
      loop.clear();
      for (uint32_t index : face) loop.push_back(source.vertices[index]);
      local.clear();
      triangulatePolygon(loop, local);
      for (const glm::uvec3& t : local) {
        mesh.triangles.emplace_back(face[t.x], face[t.y], face[t.z]);
        mesh.faceIds.push_back(firstFace[oi] + uint32_t(f));
        mesh.materials.push_back(source.material);
      }
    }
  });

  scene.faceCount = firstFace.back();
  finalizeScene(scene);
  return scene;
}

namespace {

// A text file built in a buffer and handed to an AtomicFile a few megabytes
// at a time: a crash or an error leaves the old file (or none), never a torn
// one.
class AtomicTextFile {
 public:
  explicit AtomicTextFile(std::filesystem::path path) : file_(std::move(path)) {}

  fmt::memory_buffer& buffer() { return buffer_; }

  // Hands the buffer to the OS once it holds a few megabytes.
  void flushIfFull() {
    if (buffer_.size() >= kFlushBytes) flush();
  }

  void commit() {
    flush();
    file_.commit();
  }

 private:
  static constexpr size_t kFlushBytes = size_t(4) << 20;

  void flush() {
    file_.write(std::string_view(buffer_.data(), buffer_.size()));
    buffer_.clear();
  }

  AtomicFile file_;
  fmt::memory_buffer buffer_;
};

}  // namespace

void writeObj(const PolygonScene& polygons, const std::filesystem::path& path) {
  std::filesystem::path mtlPath = path;
  mtlPath.replace_extension(".mtl");

  {
    AtomicTextFile mtl(mtlPath);
    auto out = std::back_inserter(mtl.buffer());
    for (const Material& m : polygons.materials)
      fmt::format_to(out, "newmtl {}\nKd {} {} {}\n\n", m.name, m.diffuse.r, m.diffuse.g,
                     m.diffuse.b);
    mtl.commit();
  }

  AtomicTextFile obj(path);
  auto out = std::back_inserter(obj.buffer());
  fmt::format_to(out, "# vistream generated scene '{}': {} objects, {} faces\n", polygons.name,
                 polygons.objects.size(), polygons.faceCount());
  fmt::format_to(out, "mtllib {}\n", mtlPath.filename().string());
  size_t firstVertex = 1;  // OBJ indices are 1-based and absolute
  int64_t currentMaterial = -1;
  for (const PolygonObject& o : polygons.objects) {
    fmt::format_to(out, "o {}\n", o.name);
    // fmt prints doubles in their shortest round-trip form: reading them back
    // gives the same bits.
    for (const glm::dvec3& v : o.vertices) {
      fmt::format_to(out, "v {} {} {}\n", v.x, v.y, v.z);
      obj.flushIfFull();
    }
    if (int64_t(o.material) != currentMaterial && o.material < polygons.materials.size()) {
      fmt::format_to(out, "usemtl {}\n", polygons.materials[o.material].name);
      currentMaterial = o.material;
    }
    for (const std::vector<uint32_t>& face : o.faces) {
      obj.buffer().push_back('f');
      for (uint32_t index : face) {
        obj.buffer().push_back(' ');
        const fmt::format_int number(firstVertex + index);
        obj.buffer().append(number.data(), number.data() + number.size());
      }
      obj.buffer().push_back('\n');
      obj.flushIfFull();
    }
    firstVertex += o.vertices.size();
  }
  obj.commit();
}

}  // namespace vistream
