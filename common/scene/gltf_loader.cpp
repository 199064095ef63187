// glTF 2.0 loading through tinygltf.
//
// tinygltf parses JSON and buffers; everything read out of accessors is
// bounds-checked here because a glTF file is untrusted input: an accessor can
// claim more elements than its buffer holds, and an index can point past the
// vertex array. Images are not decoded: only their references are kept.
#include <cmath>
#include <functional>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <spdlog/spdlog.h>
#include <tiny_gltf.h>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

constexpr int kTriangles = 4, kTriangleStrip = 5, kTriangleFan = 6;

// Keeps image references without decoding pixels.
bool keepImageUndecoded(tinygltf::Image*, const int, std::string*, std::string*, int, int,
                        const unsigned char*, int, void*) {
  return true;
}

class AccessorReader {
 public:
  AccessorReader(const tinygltf::Model& model, std::string file) : model_(model), file_(std::move(file)) {}

  // Reads `components` values per element as doubles, whatever the stored type.
  std::vector<double> read(int accessorIndex, int components, const std::string& what) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= model_.accessors.size())
      throwInputError("{}: {}: accessor {} does not exist", file_, what, accessorIndex);
    const tinygltf::Accessor& acc = model_.accessors[size_t(accessorIndex)];
    if (acc.sparse.isSparse)
      throwInputError("{}: {}: sparse accessor {} is not supported", file_, what, accessorIndex);
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
      throwInputError("{}: {}: accessor {} claims {} elements, more than the file's buffers can hold",
                      file_, what, accessorIndex, acc.count);
    std::vector<double> out(acc.count * size_t(components), 0.0);
    if (acc.bufferView < 0) return out;  // all zeros, per the specification
    if (size_t(acc.bufferView) >= model_.bufferViews.size())
      throwInputError("{}: {}: buffer view {} does not exist", file_, what, acc.bufferView);
    const tinygltf::BufferView& view = model_.bufferViews[size_t(acc.bufferView)];
    if (view.buffer < 0 || size_t(view.buffer) >= model_.buffers.size())
      throwInputError("{}: {}: buffer {} does not exist", file_, what, view.buffer);
    const std::vector<unsigned char>& data = model_.buffers[size_t(view.buffer)].data;
    const size_t elemSize = size_t(compSize) * size_t(components);
    const size_t stride = view.byteStride ? view.byteStride : elemSize;
    const size_t begin = view.byteOffset + acc.byteOffset;
    if (acc.count > 0) {
      const size_t last = begin + stride * (acc.count - 1) + elemSize;
      if (stride < elemSize || last > data.size() || last > view.byteOffset + view.byteLength ||
          begin < view.byteOffset)
        throwInputError("{}: {}: accessor {} reads past its buffer ({} elements of {} bytes)",
                        file_, what, accessorIndex, acc.count, elemSize);
    }
    for (size_t i = 0; i < acc.count; ++i) {
      const unsigned char* p = data.data() + begin + i * stride;
      for (int c = 0; c < components; ++c) {
        const unsigned char* q = p + size_t(c) * size_t(compSize);
        double v = 0.0;
        switch (acc.componentType) {
          case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, q, 4); v = f; break; }
          case TINYGLTF_COMPONENT_TYPE_DOUBLE: { double d; std::memcpy(&d, q, 8); v = d; break; }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = acc.normalized ? *q / 255.0 : *q; break;
          case TINYGLTF_COMPONENT_TYPE_BYTE: { const auto b = int8_t(*q); v = acc.normalized ? std::max(b / 127.0, -1.0) : b; break; }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t s; std::memcpy(&s, q, 2); v = acc.normalized ? s / 65535.0 : s; break; }
          case TINYGLTF_COMPONENT_TYPE_SHORT: { int16_t s; std::memcpy(&s, q, 2); v = acc.normalized ? std::max(s / 32767.0, -1.0) : s; break; }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { uint32_t u; std::memcpy(&u, q, 4); v = u; break; }
          case TINYGLTF_COMPONENT_TYPE_INT: { int32_t s; std::memcpy(&s, q, 4); v = s; break; }
          default: break;
        }
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
    m = glm::translate(m, glm::dvec3(node.translation[0], node.translation[1], node.translation[2]));
  if (node.rotation.size() == 4)
    m = m * glm::mat4_cast(glm::dquat(node.rotation[3], node.rotation[0], node.rotation[1],
                                      node.rotation[2]));
  if (node.scale.size() == 3)
    m = glm::scale(m, glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
  return m;
}

}  // namespace

Scene loadGltf(const std::filesystem::path& path) {
  const std::string file = path.string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throwInputError("{}: no such file", file);
  if (std::filesystem::file_size(path, ec) == 0) throwInputError("{}: file is empty", file);

  tinygltf::TinyGLTF gltf;
  gltf.SetImageLoader(keepImageUndecoded, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  const bool ok = ext == ".glb" ? gltf.LoadBinaryFromFile(&model, &err, &warn, file)
                                : gltf.LoadASCIIFromFile(&model, &err, &warn, file);
  if (!warn.empty()) spdlog::debug("{}: {}", file, warn);
  if (!ok) throwInputError("{}: {}", file, err.empty() ? std::string("not a valid glTF file") : err);

  const AccessorReader reader(model, file);
  Scene scene;
  scene.name = path.stem().string();
  scene.sources = {path};

  for (const auto& m : model.materials) {
    Material mat;
    mat.name = m.name;
    const auto& f = m.pbrMetallicRoughness.baseColorFactor;
    if (f.size() == 4) mat.baseColor = glm::vec4(float(f[0]), float(f[1]), float(f[2]), float(f[3]));
    mat.diffuse = glm::vec3(mat.baseColor);
    const int tex = m.pbrMetallicRoughness.baseColorTexture.index;
    if (tex >= 0 && size_t(tex) < model.textures.size()) {
      const int src = model.textures[size_t(tex)].source;
      if (src >= 0 && size_t(src) < model.images.size()) {
        const auto& img = model.images[size_t(src)];
        mat.baseColorTexture = !img.uri.empty() ? img.uri : (!img.name.empty() ? img.name : fmt::format("image_{}", src));
      }
    }
    scene.materials.push_back(mat);
  }
  const uint32_t defaultMaterial = uint32_t(scene.materials.size());
  scene.materials.push_back(Material::named("default"));

  // Nodes: hierarchy and rest transforms, kept for skins and animations.
  scene.nodes.resize(model.nodes.size());
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    const auto& n = model.nodes[i];
    Node& out = scene.nodes[i];
    out.name = n.name;
    if (n.translation.size() == 3) out.translation = glm::vec3(float(n.translation[0]), float(n.translation[1]), float(n.translation[2]));
    if (n.rotation.size() == 4) out.rotation = glm::vec4(float(n.rotation[0]), float(n.rotation[1]), float(n.rotation[2]), float(n.rotation[3]));
    if (n.scale.size() == 3) out.scale = glm::vec3(float(n.scale[0]), float(n.scale[1]), float(n.scale[2]));
    for (int c : n.children) {
      if (c < 0 || size_t(c) >= model.nodes.size())
        throwInputError("{}: node {} has child {} which does not exist", file, i, c);
      if (scene.nodes[size_t(c)].parent >= 0)
        throwInputError("{}: node {} has more than one parent", file, c);
      scene.nodes[size_t(c)].parent = int32_t(i);
    }
  }

  for (size_t s = 0; s < model.skins.size(); ++s) {
    const auto& sk = model.skins[s];
    Skin skin;
    skin.name = sk.name;
    for (int j : sk.joints) {
      if (j < 0 || size_t(j) >= model.nodes.size())
        throwInputError("{}: skin {} names joint node {} which does not exist", file, s, j);
      skin.joints.push_back(j);
    }
    if (sk.inverseBindMatrices >= 0) {
      const auto m = reader.read(sk.inverseBindMatrices, 16, fmt::format("skin {} inverse bind matrices", s));
      for (size_t k = 0; k + 16 <= m.size(); k += 16) {
        glm::mat4 mat;
        for (int e = 0; e < 16; ++e) glm::value_ptr(mat)[e] = float(m[k + size_t(e)]);
        skin.inverseBindMatrices.push_back(mat);
      }
    }
    scene.skins.push_back(std::move(skin));
  }

  std::vector<uint8_t> animatedNode(model.nodes.size(), 0);
  for (size_t a = 0; a < model.animations.size(); ++a) {
    const auto& an = model.animations[a];
    Animation anim;
    anim.name = an.name.empty() ? fmt::format("animation_{}", a) : an.name;
    for (size_t c = 0; c < an.channels.size(); ++c) {
      const auto& ch = an.channels[c];
      if (ch.sampler < 0 || size_t(ch.sampler) >= an.samplers.size())
        throwInputError("{}: animation {} channel {} uses sampler {} which does not exist", file, a, c, ch.sampler);
      if (ch.target_node < 0 || size_t(ch.target_node) >= model.nodes.size()) continue;
      AnimationChannel out;
      out.node = ch.target_node;
      int comps = 3;
      if (ch.target_path == "translation") out.path = AnimationChannel::Path::Translation;
      else if (ch.target_path == "rotation") { out.path = AnimationChannel::Path::Rotation; comps = 4; }
      else if (ch.target_path == "scale") out.path = AnimationChannel::Path::Scale;
      else continue;  // morph weights are not used
      const auto& sampler = an.samplers[size_t(ch.sampler)];
      if (sampler.interpolation == "STEP") out.interpolation = AnimationChannel::Interpolation::Step;
      else if (sampler.interpolation == "CUBICSPLINE") out.interpolation = AnimationChannel::Interpolation::CubicSpline;
      const std::string what = fmt::format("animation '{}' channel {}", anim.name, c);
      for (double t : reader.read(sampler.input, 1, what + " times")) out.times.push_back(float(t));
      const auto values = reader.read(sampler.output, comps, what + " values");
      for (size_t k = 0; k + size_t(comps) <= values.size(); k += size_t(comps))
        out.values.emplace_back(float(values[k]), float(values[k + 1]), float(values[k + 2]),
                                comps == 4 ? float(values[k + 3]) : 0.0f);
      if (!out.times.empty()) anim.duration = std::max(anim.duration, out.times.back());
      animatedNode[size_t(out.node)] = 1;
      anim.channels.push_back(std::move(out));
    }
    scene.animations.push_back(std::move(anim));
  }

  // Geometry: depth-first over the default scene (or every root when there is
  // none), world transforms in double, one object per mesh instance.
  struct Pending {
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
  std::vector<Pending> pending;
  std::vector<int> roots;
  if (model.defaultScene >= 0 && size_t(model.defaultScene) < model.scenes.size())
    roots = model.scenes[size_t(model.defaultScene)].nodes;
  else if (!model.scenes.empty())
    roots = model.scenes[0].nodes;
  else
    for (size_t i = 0; i < scene.nodes.size(); ++i)
      if (scene.nodes[i].parent < 0) roots.push_back(int(i));

  std::vector<uint8_t> visited(model.nodes.size(), 0);
  std::function<void(int, const glm::dmat4&, bool)> visit = [&](int ni, const glm::dmat4& parent, bool animatedAbove) {
    if (ni < 0 || size_t(ni) >= model.nodes.size())
      throwInputError("{}: scene refers to node {} which does not exist", file, ni);
    if (visited[size_t(ni)]) throwInputError("{}: node {} is reached twice (cycle or shared child)", file, ni);
    visited[size_t(ni)] = 1;
    const auto& node = model.nodes[size_t(ni)];
    const glm::dmat4 world = parent * localMatrix(node);
    const bool animated = animatedAbove || animatedNode[size_t(ni)];
    if (node.mesh >= 0) {
      if (size_t(node.mesh) >= model.meshes.size())
        throwInputError("{}: node {} uses mesh {} which does not exist", file, ni, node.mesh);
      const auto& mesh = model.meshes[size_t(node.mesh)];
      Pending obj;
      obj.name = !node.name.empty() ? node.name : (!mesh.name.empty() ? mesh.name : fmt::format("node_{}", ni));
      obj.skin = node.skin >= 0 && size_t(node.skin) < model.skins.size() ? node.skin : -1;
      obj.dynamic = obj.skin >= 0 || animated;
      // Skinned vertices live in the skin's bind space: the mesh node's own
      // transform is ignored, as the glTF specification requires.
      const glm::dmat4 xf = obj.skin >= 0 ? glm::dmat4(1.0) : world;
      for (size_t p = 0; p < mesh.primitives.size(); ++p) {
        const auto& prim = mesh.primitives[p];
        const std::string what = fmt::format("mesh '{}' primitive {}", mesh.name, p);
        if (prim.mode != kTriangles && prim.mode != kTriangleStrip && prim.mode != kTriangleFan && prim.mode != -1) {
          spdlog::warn("{}: {} has mode {} (not triangles); skipped", file, what, prim.mode);
          continue;
        }
        const auto posIt = prim.attributes.find("POSITION");
        if (posIt == prim.attributes.end()) throwInputError("{}: {} has no POSITION attribute", file, what);
        const auto pos = reader.read(posIt->second, 3, what + " POSITION");
        const size_t nv = pos.size() / 3;
        const uint32_t base = uint32_t(obj.positions.size());
        for (size_t v = 0; v < nv; ++v)
          obj.positions.push_back(glm::dvec3(xf * glm::dvec4(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2], 1.0)));
        auto attr = [&](const char* key, int comps) -> std::vector<double> {
          const auto it = prim.attributes.find(key);
          if (it == prim.attributes.end()) return {};
          auto values = reader.read(it->second, comps, what + " " + key);
          if (values.size() != nv * size_t(comps))
            throwInputError("{}: {} {} has {} elements, POSITION has {}", file, what, key, values.size() / size_t(comps), nv);
          return values;
        };
        const auto uv = attr("TEXCOORD_0", 2);
        const auto joints = attr("JOINTS_0", 4);
        const auto weights = attr("WEIGHTS_0", 4);
        // Per-vertex attributes stay aligned with positions across
        // primitives: a primitive without one pads it when another has it.
        if (!uv.empty() || !obj.texcoords.empty()) {
          obj.texcoords.resize(base, glm::vec2(0.0f));
          for (size_t v = 0; v < nv; ++v)
            obj.texcoords.push_back(uv.empty() ? glm::vec2(0.0f) : glm::vec2(float(uv[2 * v]), float(uv[2 * v + 1])));
        }
        if (!joints.empty() || !weights.empty() || !obj.joints.empty()) {
          obj.joints.resize(base, glm::u16vec4(0));
          obj.weights.resize(base, glm::vec4(0.0f));
          for (size_t v = 0; v < nv; ++v) {
            obj.joints.push_back(joints.empty() ? glm::u16vec4(0) : glm::u16vec4(uint16_t(joints[4 * v]), uint16_t(joints[4 * v + 1]), uint16_t(joints[4 * v + 2]), uint16_t(joints[4 * v + 3])));
            obj.weights.push_back(weights.empty() ? glm::vec4(0.0f) : glm::vec4(float(weights[4 * v]), float(weights[4 * v + 1]), float(weights[4 * v + 2]), float(weights[4 * v + 3])));
          }
        }
        std::vector<uint32_t> idx;
        if (prim.indices >= 0) {
          for (double d : reader.read(prim.indices, 1, what + " indices")) {
            if (d >= double(nv))
              throwInputError("{}: {}: index {} is out of range ({} vertices)", file, what, uint64_t(d), nv);
            idx.push_back(uint32_t(d));
          }
        } else {
          for (size_t v = 0; v < nv; ++v) idx.push_back(uint32_t(v));
        }
        const uint32_t mat = prim.material >= 0 && size_t(prim.material) < defaultMaterial ? uint32_t(prim.material) : defaultMaterial;
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
            spdlog::warn("{}: {}: {} indices is not a multiple of 3; the last {} are ignored", file, what, idx.size(), idx.size() % 3);
          for (size_t k = 0; k + 2 < idx.size(); k += 3) emit(idx[k], idx[k + 1], idx[k + 2]);
        }
      }
      if (!obj.triangles.empty()) pending.push_back(std::move(obj));
    }
    for (int c : node.children) visit(c, world, animated);
  };
  for (int r : roots) visit(r, glm::dmat4(1.0), false);
  if (pending.empty()) throwInputError("{}: no triangle geometry in the scene", file);

  Box3d bounds;
  for (const auto& p : pending) for (const auto& v : p.positions) bounds.extend(v);
  scene.origin = glm::floor(bounds.center());
  uint32_t faceId = 0;
  for (auto& p : pending) {
    Object obj;
    obj.name = p.name;
    obj.dynamic = p.dynamic;
    obj.skin = p.skin;
    for (const auto& v : p.positions) obj.mesh.positions.push_back(glm::vec3(v - scene.origin));
    obj.mesh.triangles = std::move(p.triangles);
    obj.mesh.materials = std::move(p.materials);
    obj.mesh.texcoords = std::move(p.texcoords);
    obj.mesh.joints = std::move(p.joints);
    obj.mesh.weights = std::move(p.weights);
    for (size_t t = 0; t < obj.mesh.triangles.size(); ++t) obj.mesh.faceIds.push_back(faceId++);
    scene.objects.push_back(std::move(obj));
  }
  scene.faceCount = faceId;
  finalizeScene(scene);
  return scene;
}

}  // namespace vistream
