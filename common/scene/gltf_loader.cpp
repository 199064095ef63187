// glTF 2.0 loading through tinygltf.
//
// tinygltf parses JSON and buffers; everything read out of accessors is
// bounds-checked here because a glTF file is untrusted input: an accessor can
// claim more elements than its buffer holds, and an index can point past the
// vertex array. Images are not decoded: only their references are kept.
//
// Before tinygltf sees the bytes, this file checks what tinygltf does not:
// the .glb container (header and chunk lengths against the file size), the
// JSON nesting depth (tinygltf converts `extras` recursively) and the size of
// every file it reads. After parsing and before building meshes, the
// triangles and vertices every mesh instance will produce are counted from
// accessor counts against SceneLimits. The node hierarchy is walked with an
// explicit stack: a chain of 20,000 nodes must not overflow the call stack.
#include <spdlog/spdlog.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <limits>
#include <string_view>
#include <type_traits>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

constexpr int kTriangles = 4, kTriangleStrip = 5, kTriangleFan = 6;

uint32_t readU32(const std::string& bytes, size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, bytes.data() + at, 4);  // glb is little-endian, as is every target we build for
  return v;
}

// Validates the binary glTF container against the file's size and returns
// its JSON chunk. tinygltf's own checks give confusing messages ("must have 4
// bytes or more bytes, but got 4") and leave the BIN chunk's 8-byte header out
// of its bound. Layout: 12-byte header (magic, version, length), then chunks
// of (length, type, payload); the first is JSON, the optional second BIN.
std::string_view glbJsonChunk(const std::string& bytes, const std::string& file) {
  constexpr uint32_t kMagic = 0x46546C67, kJson = 0x4E4F534A, kBin = 0x004E4942;
  const uint64_t size = bytes.size();
  if (size < 12)
    throwInputError("{}: {} bytes, too short for a binary glTF header (12 bytes)", file, size);
  if (readU32(bytes, 0) != kMagic)
    throwInputError("{}: not a binary glTF file (it does not start with 'glTF')", file);
  if (const uint32_t version = readU32(bytes, 4); version != 2)
    throwInputError(InputErrorCode::Unsupported,
                    "{}: binary glTF version {} is not supported (expected 2)", file, version);
  const uint64_t length = readU32(bytes, 8);
  if (length > size)
    throwInputError("{}: the glb header declares {} bytes, but the file has only {}", file, length,
                    size);
  if (length < 20)
    throwInputError("{}: the glb declares {} bytes, too short for a JSON chunk header", file,
                    length);
  const uint64_t jsonLength = readU32(bytes, 12);
  if (readU32(bytes, 16) != kJson) throwInputError("{}: the first glb chunk is not JSON", file);
  if (20 + jsonLength > length)
    throwInputError("{}: the JSON chunk length {} exceeds the file size ({} bytes)", file,
                    jsonLength, length);
  const uint64_t next = 20 + jsonLength;
  if (next < length) {
    if (next + 8 > length)
      throwInputError("{}: truncated chunk header at byte {} ({} bytes in the file)", file, next,
                      length);
    const uint64_t chunkLength = readU32(bytes, size_t(next));
    const bool bin = readU32(bytes, size_t(next) + 4) == kBin;
    if (next + 8 + chunkLength > length)
      throwInputError("{}: the {} chunk length {} at byte {} exceeds the file size ({} bytes)",
                      file, bin ? "BIN" : "second", chunkLength, next, length);
  }
  return std::string_view(bytes).substr(20, size_t(jsonLength));
}

// tinygltf reads external buffers and images through this: the same checks
// and size limit as the scene file itself.
bool readLimitedFile(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                     void* userData) {
  try {
    const std::string bytes = readSceneFile(path, *static_cast<const SceneLimits*>(userData));
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const InputError& e) {
    if (err) *err = e.what();
    return false;
  }
}

// Decodes no pixels (the lighting bake does, common/light/texture.h). An
// image given as a data URI has no other home, so its encoded bytes are kept
// in `image`; a buffer view's are read later with checked bounds
// (embeddedImage), and an external file is read again by name.
bool keepImageUndecoded(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                        const unsigned char* bytes, int size, void*) {
  if (image->bufferView < 0 && image->uri.empty() && bytes && size > 0) {
    image->image.assign(bytes, bytes + size);
    image->as_is = true;
  }
  return true;
}

// One component read from `q` (little-endian, any alignment), normalized
// integers mapped to [0, 1] or [-1, 1] as the glTF specification says.
template <typename T>
T readUnaligned(const unsigned char* q) {
  T v;
  std::memcpy(&v, q, sizeof(T));
  return v;
}

template <typename T>
double normalizedValue(const unsigned char* q, bool normalized) {
  const T v = readUnaligned<T>(q);
  if (!normalized) return double(v);
  constexpr double kMax = double(std::numeric_limits<T>::max());
  return std::is_signed_v<T> ? std::max(double(v) / kMax, -1.0) : double(v) / kMax;
}

double componentValue(const unsigned char* q, int componentType, bool normalized) {
  switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return readUnaligned<float>(q);
    case TINYGLTF_COMPONENT_TYPE_DOUBLE:
      return readUnaligned<double>(q);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalizedValue<uint8_t>(q, normalized);
    case TINYGLTF_COMPONENT_TYPE_BYTE:
      return normalizedValue<int8_t>(q, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return normalizedValue<uint16_t>(q, normalized);
    case TINYGLTF_COMPONENT_TYPE_SHORT:
      return normalizedValue<int16_t>(q, normalized);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
      return double(readUnaligned<uint32_t>(q));  // never normalized in glTF
    case TINYGLTF_COMPONENT_TYPE_INT:
      return double(readUnaligned<int32_t>(q));
    default:
      return 0.0;
  }
}

class AccessorReader {
 public:
  AccessorReader(const tinygltf::Model& model, std::string file)
      : model_(model), file_(std::move(file)) {}

  // Reads `components` values per element as doubles, whatever the stored type.
  std::vector<double> read(int accessorIndex, int components, const std::string& what) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= model_.accessors.size())
      throwInputError("{}: {}: accessor {} does not exist", file_, what, accessorIndex);
    const tinygltf::Accessor& acc = model_.accessors[size_t(accessorIndex)];
    if (acc.sparse.isSparse)
      throwInputError(InputErrorCode::Unsupported, "{}: {}: sparse accessor {} is not supported",
                      file_, what, accessorIndex);
    const int have = tinygltf::GetNumComponentsInType(uint32_t(acc.type));
    if (have != components)
      throwInputError("{}: {}: accessor {} has {} components, expected {}", file_, what,
                      accessorIndex, have, components);
    const int compSize = tinygltf::GetComponentSizeInBytes(uint32_t(acc.componentType));
    if (compSize <= 0)
      throwInputError("{}: {}: accessor {} has unknown component type {}", file_, what,
                      accessorIndex, acc.componentType);
    // Bound the element count by the bytes that could back it before
    // allocating anything: a count is untrusted and can be absurd.
    size_t limit = 0;
    for (const auto& buf : model_.buffers) limit += buf.data.size();
    if (acc.count > limit || acc.count > (size_t(1) << 32))
      throwInputError(
          "{}: {}: accessor {} claims {} elements, more than the file's buffers can hold", file_,
          what, accessorIndex, acc.count);
    const size_t elemSize = size_t(compSize) * size_t(components);
    if (acc.bufferView < 0) {
      // All zeros, per the specification; bounded like stored data would be.
      if (acc.count * elemSize > limit)
        throwInputError(
            "{}: {}: accessor {} claims {} elements, more than the file's buffers can "
            "hold",
            file_, what, accessorIndex, acc.count);
      return std::vector<double>(acc.count * size_t(components), 0.0);
    }
    if (size_t(acc.bufferView) >= model_.bufferViews.size())
      throwInputError("{}: {}: buffer view {} does not exist", file_, what, acc.bufferView);
    const tinygltf::BufferView& view = model_.bufferViews[size_t(acc.bufferView)];
    if (view.buffer < 0 || size_t(view.buffer) >= model_.buffers.size())
      throwInputError("{}: {}: buffer {} does not exist", file_, what, view.buffer);
    const std::vector<unsigned char>& data = model_.buffers[size_t(view.buffer)].data;
    const size_t stride = view.byteStride ? view.byteStride : elemSize;
    const size_t begin = view.byteOffset + acc.byteOffset;
    if (acc.count > 0) {
      const size_t last = begin + stride * (acc.count - 1) + elemSize;
      if (stride < elemSize || last > data.size() || last > view.byteOffset + view.byteLength ||
          begin < view.byteOffset)
        throwInputError("{}: {}: accessor {} reads past its buffer ({} elements of {} bytes)",
                        file_, what, accessorIndex, acc.count, elemSize);
    }
    // Allocated only now that the view is known to hold every element.
    std::vector<double> out(acc.count * size_t(components), 0.0);
    for (size_t i = 0; i < acc.count; ++i) {
      const unsigned char* p = data.data() + begin + i * stride;
      for (int c = 0; c < components; ++c) {
        const unsigned char* q = p + size_t(c) * size_t(compSize);
        const double v = componentValue(q, acc.componentType, acc.normalized);
        if (!std::isfinite(v))
          throwInputError("{}: {}: accessor {} element {} is not a finite number", file_, what,
                          accessorIndex, i);
        out[i * size_t(components) + size_t(c)] = v;
      }
    }
    return out;
  }

 private:
  const tinygltf::Model& model_;
  std::string file_;
};

glm::dmat4 localMatrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) return glm::make_mat4(node.matrix.data());
  glm::dmat4 m(1.0);
  if (node.translation.size() == 3)
    m = glm::translate(m,
                       glm::dvec3(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4)
    m = m * glm::mat4_cast(
                glm::dquat(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]));
  if (node.scale.size() == 3)
    m = glm::scale(m, glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
  return m;
}

// The nodes the geometry pass starts from: the default scene's roots (or the
// first scene's, or every parentless node when there is no scene).
std::vector<int> rootNodes(const tinygltf::Model& model) {
  if (model.defaultScene >= 0 && size_t(model.defaultScene) < model.scenes.size())
    return model.scenes[size_t(model.defaultScene)].nodes;
  if (!model.scenes.empty()) return model.scenes[0].nodes;
  std::vector<uint8_t> hasParent(model.nodes.size(), 0);
  for (const auto& n : model.nodes)
    for (int c : n.children)
      if (c >= 0 && size_t(c) < model.nodes.size()) hasParent[size_t(c)] = 1;
  std::vector<int> roots;
  for (size_t i = 0; i < model.nodes.size(); ++i)
    if (!hasParent[i]) roots.push_back(int(i));
  return roots;
}

uint64_t saturatingAdd(uint64_t a, uint64_t b) {
  return a > std::numeric_limits<uint64_t>::max() - b ? std::numeric_limits<uint64_t>::max()
                                                      : a + b;
}

// Counts the triangles and vertices the geometry pass will build, from
// accessor counts alone (nothing is read or allocated), and throws
// SceneLimitError over the limits. Every mesh instance counts: one mesh
// under 1,000 nodes is built 1,000 times. What the geometry pass would
// reject (missing nodes or accessors, counts no buffer can back, cycles) is
// skipped here and reported there, before it allocates.
void checkGeometryLimits(const tinygltf::Model& model, const std::vector<int>& roots,
                         const std::string& file, const SceneLimits& limits) {
  uint64_t bufferBytes = 0;
  for (const auto& b : model.buffers) bufferBytes += b.data.size();
  auto countOf = [&](int accessor) -> uint64_t {
    if (accessor < 0 || size_t(accessor) >= model.accessors.size()) return 0;
    const uint64_t count = model.accessors[size_t(accessor)].count;
    return count > bufferBytes ? 0 : count;
  };
  uint64_t triangles = 0, vertices = 0;
  std::vector<uint8_t> visited(model.nodes.size(), 0);
  std::vector<int> stack(roots.rbegin(), roots.rend());
  while (!stack.empty()) {
    const int ni = stack.back();
    stack.pop_back();
    if (ni < 0 || size_t(ni) >= model.nodes.size() || visited[size_t(ni)]) continue;
    visited[size_t(ni)] = 1;
    const auto& node = model.nodes[size_t(ni)];
    if (node.mesh >= 0 && size_t(node.mesh) < model.meshes.size()) {
      for (const auto& prim : model.meshes[size_t(node.mesh)].primitives) {
        if (prim.mode != kTriangles && prim.mode != kTriangleStrip && prim.mode != kTriangleFan &&
            prim.mode != -1)
          continue;
        const auto pos = prim.attributes.find("POSITION");
        const uint64_t nv = pos == prim.attributes.end() ? 0 : countOf(pos->second);
        const uint64_t n = prim.indices >= 0 ? countOf(prim.indices) : nv;
        const bool strip = prim.mode == kTriangleStrip || prim.mode == kTriangleFan;
        triangles = saturatingAdd(triangles, strip ? (n >= 3 ? n - 2 : 0) : n / 3);
        vertices = saturatingAdd(vertices, nv);
      }
    }
    for (auto c = node.children.rbegin(); c != node.children.rend(); ++c) stack.push_back(*c);
  }
  if (triangles > triangleLimit(limits))
    throwSceneLimit(file, triangles, triangleLimit(limits), "triangles");
  if (vertices > vertexLimit(limits))
    throwSceneLimit(file, vertices, vertexLimit(limits), "vertices");
}

// Node transforms become float in Scene::nodes (for skins and animations).
void checkNodeTransform(const tinygltf::Node& node, size_t index, const std::string& file) {
  for (const auto* values : {&node.matrix, &node.translation, &node.rotation, &node.scale})
    for (double v : *values)
      if (!std::isfinite(float(v)))
        throwInputError("{}: node {} has transform value {}, which is not a finite float", file,
                        index, v);
}

// A mesh instance while the node walk builds it; positions in file
// coordinates (double) until the scene's origin is known.
struct PendingObject {
  std::string name;
  std::vector<glm::dvec3> positions;
  std::vector<glm::vec2> texcoords;
  std::vector<glm::u16vec4> joints;
  std::vector<glm::vec4> weights;
  std::vector<glm::uvec3> triangles;
  std::vector<uint32_t> materials;
  int32_t skin = -1;
  bool dynamic = false;
};

// Parses the file with tinygltf after the checks tinygltf does not make.
// Refuses every file a glTF parsed from memory names (its images and
// buffers must be in the bytes).
bool refuseFile(std::vector<unsigned char>*, std::string* err, const std::string& path, void*) {
  if (err) *err = "a glTF read from memory cannot read the file '" + path + "'";
  return false;
}

// Parses glTF bytes: a .glb container when `binary`, else glTF JSON whose
// external files are read from `baseDir` (empty: none may be read).
tinygltf::Model parseGltfBytes(const std::string& bytes, const std::string& file, bool binary,
                               const std::string& baseDir, const SceneLimits& limits) {
  if (bytes.empty()) throwInputError("{}: file is empty", file);
  if (bytes.size() > std::numeric_limits<uint32_t>::max())
    throwInputError(InputErrorCode::TooLarge,
                    "{}: {} bytes; glTF files of 4 GiB or more are not supported", file,
                    bytes.size());
  if (binary)
    checkJsonNesting(glbJsonChunk(bytes, file), file + " (JSON chunk)");
  else
    checkJsonNesting(bytes, file);

  tinygltf::TinyGLTF gltf;
  gltf.SetImageLoader(keepImageUndecoded, nullptr);
  SceneLimits fileLimits = limits;
  gltf.SetFsCallbacks({&tinygltf::FileExists, &tinygltf::ExpandFilePath,
                       baseDir.empty() ? &refuseFile : &readLimitedFile, &tinygltf::WriteWholeFile,
                       &fileLimits});
  tinygltf::Model model;
  std::string err, warn;
  const bool ok =
      binary ? gltf.LoadBinaryFromMemory(&model, &err, &warn,
                                         reinterpret_cast<const unsigned char*>(bytes.data()),
                                         unsigned(bytes.size()), baseDir)
             : gltf.LoadASCIIFromString(&model, &err, &warn, bytes.data(), unsigned(bytes.size()),
                                        baseDir);
  if (!warn.empty()) spdlog::debug("{}: {}", file, warn);
  if (!ok)
    throwInputError("{}: {}", file, err.empty() ? std::string("not a valid glTF file") : err);
  return model;
}

tinygltf::Model parseGltf(const std::filesystem::path& path, const SceneLimits& limits) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  std::string baseDir = path.parent_path().string();
  if (baseDir.empty()) baseDir = ".";
  return parseGltfBytes(readSceneFile(path, limits), path.string(), ext == ".glb", baseDir, limits);
}

// Builds a Scene from a parsed model, one named step per part of the file.
// Every index the model holds is checked before it is used.
class GltfSceneBuilder {
 public:
  GltfSceneBuilder(const tinygltf::Model& model, const std::filesystem::path& path)
      : model_(model), file_(path.string()), reader_(model, file_) {
    scene_.name = path.stem().string();
    scene_.sources = {path};
  }

  void readMaterials() {
    for (const auto& m : model_.materials) {
      Material mat;
      mat.name = m.name;
      const auto& f = m.pbrMetallicRoughness.baseColorFactor;
      if (f.size() == 4)
        mat.baseColor = glm::vec4(float(f[0]), float(f[1]), float(f[2]), float(f[3]));
      mat.diffuse = glm::vec3(mat.baseColor);
      const int tex = m.pbrMetallicRoughness.baseColorTexture.index;
      if (tex >= 0 && size_t(tex) < model_.textures.size()) {
        const int src = model_.textures[size_t(tex)].source;
        if (src >= 0 && size_t(src) < model_.images.size()) {
          const auto& img = model_.images[size_t(src)];
          mat.baseColorTexture =
              !img.uri.empty() ? img.uri
                               : (!img.name.empty() ? img.name : fmt::format("image_{}", src));
          if (img.uri.empty()) mat.baseColorImage = embeddedImage(img, size_t(src));
        }
      }
      scene_.materials.push_back(mat);
    }
    defaultMaterial_ = uint32_t(scene_.materials.size());
    scene_.materials.push_back(Material::unassignedDefault());
  }

  // The encoded bytes of an image the file holds (a buffer view or a data
  // URI); null, with a warning, when its buffer view lies outside its buffer.
  std::shared_ptr<const std::vector<uint8_t>> embeddedImage(const tinygltf::Image& img,
                                                            size_t index) const {
    if (img.bufferView < 0)
      return img.image.empty() ? nullptr : std::make_shared<const std::vector<uint8_t>>(img.image);
    const auto& views = model_.bufferViews;
    if (size_t(img.bufferView) < views.size()) {
      const tinygltf::BufferView& view = views[size_t(img.bufferView)];
      if (view.buffer >= 0 && size_t(view.buffer) < model_.buffers.size()) {
        const auto& data = model_.buffers[size_t(view.buffer)].data;
        if (view.byteOffset <= data.size() && view.byteLength <= data.size() - view.byteOffset)
          return std::make_shared<const std::vector<uint8_t>>(
              data.begin() + std::ptrdiff_t(view.byteOffset),
              data.begin() + std::ptrdiff_t(view.byteOffset + view.byteLength));
      }
    }
    spdlog::warn("{}: image {} lies outside its buffer; its material keeps its base colour", file_,
                 index);
    return nullptr;
  }

  // Nodes: hierarchy and rest transforms, kept for skins and animations.
  void readNodes() {
    scene_.nodes.resize(model_.nodes.size());
    for (size_t i = 0; i < model_.nodes.size(); ++i) {
      const auto& n = model_.nodes[i];
      Node& out = scene_.nodes[i];
      out.name = n.name;
      checkNodeTransform(n, i, file_);
      if (n.translation.size() == 3)
        out.translation =
            glm::vec3(float(n.translation[0]), float(n.translation[1]), float(n.translation[2]));
      if (n.rotation.size() == 4)
        out.rotation = glm::vec4(float(n.rotation[0]), float(n.rotation[1]), float(n.rotation[2]),
                                 float(n.rotation[3]));
      if (n.scale.size() == 3)
        out.scale = glm::vec3(float(n.scale[0]), float(n.scale[1]), float(n.scale[2]));
      for (int c : n.children) {
        if (c < 0 || size_t(c) >= model_.nodes.size())
          throwInputError("{}: node {} has child {} which does not exist", file_, i, c);
        if (scene_.nodes[size_t(c)].parent >= 0)
          throwInputError("{}: node {} has more than one parent", file_, c);
        scene_.nodes[size_t(c)].parent = int32_t(i);
      }
    }
  }

  void readSkins() {
    for (size_t s = 0; s < model_.skins.size(); ++s) {
      const auto& sk = model_.skins[s];
      Skin skin;
      skin.name = sk.name;
      for (int j : sk.joints) {
        if (j < 0 || size_t(j) >= model_.nodes.size())
          throwInputError("{}: skin {} names joint node {} which does not exist", file_, s, j);
        skin.joints.push_back(j);
      }
      if (sk.inverseBindMatrices >= 0) {
        const auto m = reader_.read(sk.inverseBindMatrices, 16,
                                    fmt::format("skin {} inverse bind matrices", s));
        for (size_t k = 0; k + 16 <= m.size(); k += 16) {
          glm::mat4 mat;
          for (int e = 0; e < 16; ++e) glm::value_ptr(mat)[e] = float(m[k + size_t(e)]);
          skin.inverseBindMatrices.push_back(mat);
        }
      }
      scene_.skins.push_back(std::move(skin));
    }
  }

  // Animations, and which nodes they move (their meshes become dynamic).
  void readAnimations() {
    animatedNode_.assign(model_.nodes.size(), 0);
    for (size_t a = 0; a < model_.animations.size(); ++a) {
      const auto& an = model_.animations[a];
      Animation anim;
      anim.name = an.name.empty() ? fmt::format("animation_{}", a) : an.name;
      for (size_t c = 0; c < an.channels.size(); ++c) {
        AnimationChannel out;
        if (!readChannel(an, a, c, anim.name, out)) continue;
        if (!out.times.empty()) anim.duration = std::max(anim.duration, out.times.back());
        animatedNode_[size_t(out.node)] = 1;
        anim.channels.push_back(std::move(out));
      }
      scene_.animations.push_back(std::move(anim));
    }
  }

  // Geometry: depth-first, pre-order, children in order, on an explicit
  // stack, over the default scene (or every root when there is none); world
  // transforms in double, one object per mesh instance.
  void walkNodes(const std::vector<int>& roots) {
    struct Visit {
      int node;
      glm::dmat4 parent;
      bool animatedAbove;
    };
    std::vector<Visit> stack;
    for (auto r = roots.rbegin(); r != roots.rend(); ++r)
      stack.push_back({*r, glm::dmat4(1.0), false});
    std::vector<uint8_t> visited(model_.nodes.size(), 0);
    while (!stack.empty()) {
      const Visit top = stack.back();
      stack.pop_back();
      const int ni = top.node;
      if (ni < 0 || size_t(ni) >= model_.nodes.size())
        throwInputError("{}: scene refers to node {} which does not exist", file_, ni);
      if (visited[size_t(ni)])
        throwInputError("{}: node {} is reached twice (cycle or shared child)", file_, ni);
      visited[size_t(ni)] = 1;
      const auto& node = model_.nodes[size_t(ni)];
      const glm::dmat4 world = top.parent * localMatrix(node);
      const bool animated = top.animatedAbove || animatedNode_[size_t(ni)];
      if (node.mesh >= 0) buildMeshInstance(ni, world, animated);
      for (auto c = node.children.rbegin(); c != node.children.rend(); ++c)
        stack.push_back({*c, world, animated});
    }
    if (pending_.empty()) throwInputError("{}: no triangle geometry in the scene", file_);
  }

  // The local origin, the float range check, and the objects with face IDs
  // in file order.
  Scene finish() {
    Box3d bounds;
    for (const auto& p : pending_)
      for (const auto& v : p.positions) bounds.extend(v);
    scene_.origin = glm::floor(bounds.center());
    checkFloatRange();
    uint32_t faceId = 0;
    for (auto& p : pending_) {
      Object obj;
      obj.name = p.name;
      obj.dynamic = p.dynamic;
      obj.skin = p.skin;
      for (const auto& v : p.positions) obj.mesh.positions.push_back(glm::vec3(v - scene_.origin));
      obj.mesh.triangles = std::move(p.triangles);
      obj.mesh.materials = std::move(p.materials);
      obj.mesh.texcoords = std::move(p.texcoords);
      obj.mesh.joints = std::move(p.joints);
      obj.mesh.weights = std::move(p.weights);
      for (size_t t = 0; t < obj.mesh.triangles.size(); ++t) obj.mesh.faceIds.push_back(faceId++);
      scene_.objects.push_back(std::move(obj));
    }
    scene_.faceCount = faceId;
    finalizeScene(scene_);
    return std::move(scene_);
  }

 private:
  // One channel of animation `a`; false for channels that are not used
  // (morph weights, targets that do not exist).
  bool readChannel(const tinygltf::Animation& an, size_t a, size_t c, const std::string& name,
                   AnimationChannel& out) const {
    const auto& ch = an.channels[c];
    if (ch.sampler < 0 || size_t(ch.sampler) >= an.samplers.size())
      throwInputError("{}: animation {} channel {} uses sampler {} which does not exist", file_, a,
                      c, ch.sampler);
    if (ch.target_node < 0 || size_t(ch.target_node) >= model_.nodes.size()) return false;
    out.node = ch.target_node;
    int comps = 3;
    if (ch.target_path == "translation") {
      out.path = AnimationChannel::Path::Translation;
    } else if (ch.target_path == "rotation") {
      out.path = AnimationChannel::Path::Rotation;
      comps = 4;
    } else if (ch.target_path == "scale") {
      out.path = AnimationChannel::Path::Scale;
    } else {
      return false;
    }
    const auto& sampler = an.samplers[size_t(ch.sampler)];
    if (sampler.interpolation == "STEP")
      out.interpolation = AnimationChannel::Interpolation::Step;
    else if (sampler.interpolation == "CUBICSPLINE")
      out.interpolation = AnimationChannel::Interpolation::CubicSpline;
    const std::string what = fmt::format("animation '{}' channel {}", name, c);
    for (double t : reader_.read(sampler.input, 1, what + " times")) out.times.push_back(float(t));
    const auto values = reader_.read(sampler.output, comps, what + " values");
    for (size_t k = 0; k + size_t(comps) <= values.size(); k += size_t(comps))
      out.values.emplace_back(float(values[k]), float(values[k + 1]), float(values[k + 2]),
                              comps == 4 ? float(values[k + 3]) : 0.0f);
    return true;
  }

  void buildMeshInstance(int ni, const glm::dmat4& world, bool animated) {
    const auto& node = model_.nodes[size_t(ni)];
    if (size_t(node.mesh) >= model_.meshes.size())
      throwInputError("{}: node {} uses mesh {} which does not exist", file_, ni, node.mesh);
    const auto& mesh = model_.meshes[size_t(node.mesh)];
    PendingObject obj;
    obj.name = !node.name.empty() ? node.name
                                  : (!mesh.name.empty() ? mesh.name : fmt::format("node_{}", ni));
    obj.skin = node.skin >= 0 && size_t(node.skin) < model_.skins.size() ? node.skin : -1;
    obj.dynamic = obj.skin >= 0 || animated;
    // Skinned vertices live in the skin's bind space: the mesh node's own
    // transform is ignored, as the glTF specification requires.
    const glm::dmat4 xf = obj.skin >= 0 ? glm::dmat4(1.0) : world;
    for (size_t p = 0; p < mesh.primitives.size(); ++p)
      readPrimitive(mesh.primitives[p], fmt::format("mesh '{}' primitive {}", mesh.name, p), xf,
                    obj);
    if (!obj.triangles.empty()) pending_.push_back(std::move(obj));
  }

  // A per-vertex attribute, empty when the primitive has none; it must
  // have one element per position.
  std::vector<double> readAttribute(const tinygltf::Primitive& prim, const char* key, int comps,
                                    size_t nv, const std::string& what) const {
    const auto it = prim.attributes.find(key);
    if (it == prim.attributes.end()) return {};
    auto values = reader_.read(it->second, comps, what + " " + key);
    if (values.size() != nv * size_t(comps))
      throwInputError("{}: {} {} has {} elements, POSITION has {}", file_, what, key,
                      values.size() / size_t(comps), nv);
    return values;
  }

  void readPrimitive(const tinygltf::Primitive& prim, const std::string& what, const glm::dmat4& xf,
                     PendingObject& obj) const {
    if (prim.mode != kTriangles && prim.mode != kTriangleStrip && prim.mode != kTriangleFan &&
        prim.mode != -1) {
      spdlog::warn("{}: {} has mode {} (not triangles); skipped", file_, what, prim.mode);
      return;
    }
    const auto posIt = prim.attributes.find("POSITION");
    if (posIt == prim.attributes.end())
      throwInputError("{}: {} has no POSITION attribute", file_, what);
    const auto pos = reader_.read(posIt->second, 3, what + " POSITION");
    const size_t nv = pos.size() / 3;
    const uint32_t base = uint32_t(obj.positions.size());
    for (size_t v = 0; v < nv; ++v)
      obj.positions.push_back(
          glm::dvec3(xf * glm::dvec4(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2], 1.0)));
    appendVertexAttributes(prim, what, base, nv, obj);
    const uint32_t mat = prim.material >= 0 && size_t(prim.material) < defaultMaterial_
                             ? uint32_t(prim.material)
                             : defaultMaterial_;
    appendTriangles(prim, what, readIndices(prim, what, nv), base, mat, obj);
  }

  // Per-vertex attributes stay aligned with positions across primitives: a
  // primitive without one pads it when another has it.
  void appendVertexAttributes(const tinygltf::Primitive& prim, const std::string& what,
                              uint32_t base, size_t nv, PendingObject& obj) const {
    const auto uv = readAttribute(prim, "TEXCOORD_0", 2, nv, what);
    const auto joints = readAttribute(prim, "JOINTS_0", 4, nv, what);
    const auto weights = readAttribute(prim, "WEIGHTS_0", 4, nv, what);
    if (!uv.empty() || !obj.texcoords.empty()) {
      obj.texcoords.resize(base, glm::vec2(0.0f));
      for (size_t v = 0; v < nv; ++v)
        obj.texcoords.push_back(uv.empty() ? glm::vec2(0.0f)
                                           : glm::vec2(float(uv[2 * v]), float(uv[2 * v + 1])));
    }
    if (joints.empty() && weights.empty() && obj.joints.empty()) return;
    obj.joints.resize(base, glm::u16vec4(0));
    obj.weights.resize(base, glm::vec4(0.0f));
    for (size_t v = 0; v < nv; ++v) {
      obj.joints.push_back(
          joints.empty() ? glm::u16vec4(0)
                         : glm::u16vec4(uint16_t(joints[4 * v]), uint16_t(joints[4 * v + 1]),
                                        uint16_t(joints[4 * v + 2]), uint16_t(joints[4 * v + 3])));
      obj.weights.push_back(weights.empty()
                                ? glm::vec4(0.0f)
                                : glm::vec4(float(weights[4 * v]), float(weights[4 * v + 1]),
                                            float(weights[4 * v + 2]), float(weights[4 * v + 3])));
    }
  }

  // The primitive's indices (0..nv-1 without an index accessor), each checked
  // against the vertex count.
  std::vector<uint32_t> readIndices(const tinygltf::Primitive& prim, const std::string& what,
                                    size_t nv) const {
    std::vector<uint32_t> idx;
    if (prim.indices < 0) {
      for (size_t v = 0; v < nv; ++v) idx.push_back(uint32_t(v));
      return idx;
    }
    for (double d : reader_.read(prim.indices, 1, what + " indices")) {
      if (d >= double(nv))
        throwInputError("{}: {}: index {} is out of range ({} vertices)", file_, what, uint64_t(d),
                        nv);
      idx.push_back(uint32_t(d));
    }
    return idx;
  }

  // Triangles from a list, strip (alternate windings) or fan.
  void appendTriangles(const tinygltf::Primitive& prim, const std::string& what,
                       const std::vector<uint32_t>& idx, uint32_t base, uint32_t mat,
                       PendingObject& obj) const {
    auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
      obj.triangles.emplace_back(base + a, base + b, base + c);
      obj.materials.push_back(mat);
    };
    if (prim.mode == kTriangleStrip) {
      for (size_t k = 0; k + 2 < idx.size(); ++k)
        k % 2 == 0 ? emit(idx[k], idx[k + 1], idx[k + 2]) : emit(idx[k + 1], idx[k], idx[k + 2]);
    } else if (prim.mode == kTriangleFan) {
      for (size_t k = 1; k + 1 < idx.size(); ++k) emit(idx[0], idx[k], idx[k + 1]);
    } else {
      if (idx.size() % 3 != 0)
        spdlog::warn("{}: {}: {} indices is not a multiple of 3; the last {} are ignored", file_,
                     what, idx.size(), idx.size() % 3);
      for (size_t k = 0; k + 2 < idx.size(); k += 3) emit(idx[k], idx[k + 1], idx[k + 2]);
    }
  }

  // Finite POSITION floats can still overflow: node transforms are applied
  // in double, and the result is stored as float relative to the origin. One
  // far vertex moves the origin so that others fail too: blame the failing
  // vertex farthest from zero.
  void checkFloatRange() const {
    const PendingObject* worstObject = nullptr;
    size_t worstVertex = 0;
    double worstMagnitude = -1.0;
    for (const auto& p : pending_)
      for (size_t k = 0; k < p.positions.size(); ++k) {
        const glm::dvec3 v = p.positions[k];
        const glm::vec3 local(v - scene_.origin);
        if (std::isfinite(local.x) && std::isfinite(local.y) && std::isfinite(local.z)) continue;
        const double magnitude = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
        if (!(magnitude <= worstMagnitude)) {  // NaN (from inf - inf) counts as farthest
          worstObject = &p;
          worstVertex = k;
          worstMagnitude = magnitude;
        }
      }
    if (!worstObject) return;
    const glm::dvec3 v = worstObject->positions[worstVertex];
    const glm::dvec3& o = scene_.origin;
    throwInputError(
        "{}: object '{}' vertex {} ({}, {}, {}) is too far from the scene's local origin "
        "({}, {}, {}) to store in single precision",
        file_, worstObject->name, worstVertex, v.x, v.y, v.z, o.x, o.y, o.z);
  }

  const tinygltf::Model& model_;
  std::string file_;
  AccessorReader reader_;
  Scene scene_;
  uint32_t defaultMaterial_ = 0;
  std::vector<uint8_t> animatedNode_;
  std::vector<PendingObject> pending_;
};

Scene buildGltfScene(const tinygltf::Model& model, const std::filesystem::path& path,
                     const SceneLimits& limits) {
  const std::vector<int> roots = rootNodes(model);
  checkGeometryLimits(model, roots, path.string(), limits);
  GltfSceneBuilder builder(model, path);
  builder.readMaterials();
  builder.readNodes();
  builder.readSkins();
  builder.readAnimations();
  builder.walkNodes(roots);
  return builder.finish();
}

}  // namespace

Scene loadGltf(const std::filesystem::path& path, const SceneLimits& limits) {
  return buildGltfScene(parseGltf(path, limits), path, limits);
}

Scene loadGlbFromMemory(std::string_view bytes, const std::string& name,
                        const SceneLimits& limits) {
  if (bytes.size() > limits.maxFileBytes)
    throwInputError(InputErrorCode::TooLarge, "{}: {} bytes, more than the limit of {}", name,
                    bytes.size(), limits.maxFileBytes);
  return buildGltfScene(parseGltfBytes(std::string(bytes), name, true, "", limits), name, limits);
}

}  // namespace vistream
