// OBJ loading: tinyobjloader parses, a line scan of our own validates.
//
// tinyobjloader is lenient in ways that would silently corrupt face IDs or
// geometry: it reads "nan" as 0, drops faces with fewer than three vertices
// and keeps out-of-range indices. So a first pass over the text records the
// line of every `v` and `f` statement and rejects what is wrong with a
// file:line message; tinyobjloader then does the parsing proper (groups,
// materials, index forms) and the two passes are cross-checked. The first
// pass also counts the triangles and vertices the file will produce and stops
// at SceneLimits before tinyobjloader allocates anything, and it rejects
// indices that tinyobjloader's atoi could not represent.
#include <spdlog/spdlog.h>
#include <tiny_obj_loader.h>

#include <algorithm>
#include <charconv>
#include <climits>
#include <cmath>
#include <unordered_map>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"
#include "common/scene/triangulate.h"

namespace vistream {
namespace {

// tinyobjloader stores the vertex count of a face in an unsigned char.
constexpr size_t kMaxFaceVertices = 255;

bool isSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

struct LineScan {
  size_t vertexCount = 0;
  size_t faceCount = 0;
  std::vector<uint32_t> faceLines;  // 1-based line of each face, in order
};

// Splits a line into whitespace-separated tokens (views into the line).
void tokenize(std::string_view line, std::vector<std::string_view>& tokens) {
  tokens.clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isSpace(line[i])) ++i;
    size_t j = i;
    while (j < line.size() && !isSpace(line[j])) ++j;
    if (j > i) tokens.push_back(line.substr(i, j - i));
    i = j;
  }
}

// Calls visit(lineNo, tokens) for every non-empty line, comments removed.
template <typename Visit>
void forEachStatement(std::string_view text, Visit&& visit) {
  std::vector<std::string_view> tokens;
  uint32_t lineNo = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++lineNo;
    const size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    tokenize(line, tokens);
    if (!tokens.empty() && !visit(lineNo, tokens)) return;
  }
}

// What the statements of a whole file add up to; counted only to report a
// limit, so nothing is validated.
struct StatementCounts {
  uint64_t vertices = 0, texcoords = 0, normals = 0, triangles = 0;
};

StatementCounts countStatements(std::string_view text) {
  StatementCounts c;
  forEachStatement(text, [&](uint32_t, const std::vector<std::string_view>& tokens) {
    const std::string_view key = tokens[0];
    if (key == "v")
      ++c.vertices;
    else if (key == "vt")
      ++c.texcoords;
    else if (key == "vn")
      ++c.normals;
    else if (key == "f" && tokens.size() >= 4)
      c.triangles += tokens.size() - 3;
    return true;
  });
  return c;
}

// The 1-based line of the `v` statement of vertex `index` (0-based).
uint32_t lineOfVertex(std::string_view text, size_t index) {
  uint32_t found = 0;
  size_t seen = 0;
  forEachStatement(text, [&](uint32_t lineNo, const std::vector<std::string_view>& tokens) {
    if (tokens[0] != "v") return true;
    if (seen++ < index) return true;
    found = lineNo;
    return false;
  });
  return found;
}

LineScan scanLines(std::string_view text, const std::string& name, const SceneLimits& limits) {
  const uint64_t maxTriangles = triangleLimit(limits);
  const uint64_t maxVertices = vertexLimit(limits);
  LineScan scan;
  uint64_t triangles = 0, texcoords = 0, normals = 0;
  std::vector<long long> pendingIndices;  // positive indices, checked once all vertices are known
  std::vector<uint32_t> pendingLines;
  // Over a limit: count the whole file (without validating) to report it,
  // naming the triangles when they are over too: the limit users set.
  auto overLimit = [&]() {
    const StatementCounts all = countStatements(text);
    if (all.triangles > maxTriangles)
      throwSceneLimit(name, all.triangles, maxTriangles, "triangles");
    if (all.vertices > maxVertices) throwSceneLimit(name, all.vertices, maxVertices, "vertices");
    if (all.texcoords > maxVertices)
      throwSceneLimit(name, all.texcoords, maxVertices, "texture coordinates");
    throwSceneLimit(name, all.normals, maxVertices, "normals");
  };
  forEachStatement(text, [&](uint32_t lineNo, const std::vector<std::string_view>& tokens) {
    const std::string_view key = tokens[0];
    if (key == "v") {
      if (tokens.size() < 4)
        throwInputError("{}:{}: vertex has {} coordinates, expected 3", name, lineNo,
                        tokens.size() - 1);
      for (size_t k = 1; k <= 3; ++k) {
        double value = 0.0;
        std::string_view num = tokens[k];
        if (num.size() > 1 && num.front() == '+') num.remove_prefix(1);  // from_chars rejects '+'
        const auto [ptr, ec] = std::from_chars(num.data(), num.data() + num.size(), value);
        if (ec != std::errc() || ptr != num.data() + num.size() || !std::isfinite(value))
          throwInputError("{}:{}: vertex coordinate '{}' is not a finite number", name, lineNo,
                          tokens[k]);
      }
      if (++scan.vertexCount > maxVertices) overLimit();
    } else if (key == "vt") {
      if (++texcoords > maxVertices) overLimit();
    } else if (key == "vn") {
      if (++normals > maxVertices) overLimit();
    } else if (key == "f") {
      const size_t n = tokens.size() - 1;
      if (n < 3)
        throwInputError("{}:{}: face has {} vertices, at least 3 are needed", name, lineNo, n);
      if (n > kMaxFaceVertices)
        throwInputError("{}:{}: face has {} vertices, at most {} are supported", name, lineNo, n,
                        kMaxFaceVertices);
      // Checked before anything of the face is stored: a file over the limit
      // fails here, at the first face past it, before the parser runs.
      triangles += n - 2;
      if (triangles > maxTriangles) overLimit();
      for (size_t k = 1; k <= n; ++k) {
        const std::string_view token = tokens[k];
        std::string_view tok = token.substr(0, token.find('/'));
        if (tok.size() > 1 && tok.front() == '+') tok.remove_prefix(1);
        long long idx = 0;
        const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), idx);
        if (ec != std::errc() || ptr != tok.data() + tok.size() || idx == 0)
          throwInputError("{}:{}: face vertex '{}' is not a valid index", name, lineNo, token);
        if (idx < 0) {
          // Compared without negating idx: -LLONG_MIN overflows.
          if (idx < -static_cast<long long>(scan.vertexCount))
            throwInputError("{}:{}: relative face index {} refers before the first vertex", name,
                            lineNo, idx);
        } else {
          pendingIndices.push_back(idx);
          pendingLines.push_back(lineNo);
        }
        // The texture coordinate and normal indices after the slashes go to
        // tinyobjloader's atoi, which has no defined result outside int.
        for (size_t slash = token.find('/'); slash != std::string_view::npos;) {
          const size_t next = token.find('/', slash + 1);
          std::string_view part =
              token.substr(slash + 1, next == std::string_view::npos ? std::string_view::npos
                                                                     : next - slash - 1);
          slash = next;
          if (part.size() > 1 && part.front() == '+') part.remove_prefix(1);
          if (part.empty()) continue;
          long long value = 0;
          const auto r = std::from_chars(part.data(), part.data() + part.size(), value);
          if (r.ec == std::errc::result_out_of_range ||
              (r.ec == std::errc() && (value > INT_MAX || value < INT_MIN)))
            throwInputError("{}:{}: face vertex '{}' has an index out of range", name, lineNo,
                            token);
        }
      }
      scan.faceLines.push_back(lineNo);
      ++scan.faceCount;
    }
    return true;
  });
  for (size_t i = 0; i < pendingIndices.size(); ++i)
    if (pendingIndices[i] > (long long)scan.vertexCount)
      throwInputError("{}:{}: face index {} is out of range ({} vertices in the file)", name,
                      pendingLines[i], pendingIndices[i], scan.vertexCount);
  if (scan.faceCount == 0) {
    if (text.find_first_not_of(" \t\r\n") == std::string_view::npos)
      throwInputError("{}: file is empty", name);
    size_t lines = size_t(std::count(text.begin(), text.end(), '\n'));
    if (!text.empty() && text.back() != '\n') ++lines;
    throwInputError("{}: file has no faces ({} vertices, {} lines)", name, scan.vertexCount, lines);
  }
  return scan;
}

Material toMaterial(const tinyobj::material_t& m) {
  Material out;
  out.name = m.name;
  out.diffuse = glm::vec3(float(m.diffuse[0]), float(m.diffuse[1]), float(m.diffuse[2]));
  out.baseColor = glm::vec4(out.diffuse, float(m.dissolve));
  out.baseColorTexture = m.diffuse_texname;
  return out;
}

}  // namespace

Scene loadObjFromMemory(std::string_view objText, const std::string& displayName,
                        std::string_view mtlText, const SceneLimits& limits) {
  if (objText.size() > limits.maxFileBytes)
    throwInputError("{}: the file has {} bytes, more than the limit of {} bytes for a scene file",
                    displayName, objText.size(), limits.maxFileBytes);
  const LineScan scan = scanLines(objText, displayName, limits);

  tinyobj::ObjReaderConfig config;
  config.triangulate = false;  // we triangulate concave polygons ourselves
  config.vertex_color = false;
  tinyobj::ObjReader reader;
  // tinyobjloader reads a comment after a face as indices: blank every
  // comment out (the line scan above already ignores them).
  std::string text(objText);
  for (size_t at = text.find('#'); at != std::string::npos; at = text.find('#', at)) {
    const size_t end = text.find('\n', at);
    std::fill(text.begin() + std::ptrdiff_t(at),
              end == std::string::npos ? text.end() : text.begin() + std::ptrdiff_t(end), ' ');
    at = end == std::string::npos ? text.size() : end;
  }
  if (!reader.ParseFromString(text, std::string(mtlText), config))
    throwInputError("{}: {}", displayName, reader.Error());
  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  const auto& shapes = reader.GetShapes();

  size_t parsedFaces = 0;
  for (const auto& s : shapes) parsedFaces += s.mesh.num_face_vertices.size();
  if (parsedFaces != scan.faceCount || attrib.vertices.size() != 3 * scan.vertexCount)
    throwInputError("{}: parser disagrees with line scan ({} of {} faces, {} of {} vertices)",
                    displayName, parsedFaces, scan.faceCount, attrib.vertices.size() / 3,
                    scan.vertexCount);

  Scene scene;
  scene.name = displayName;
  for (const auto& m : reader.GetMaterials()) scene.materials.push_back(toMaterial(m));
  const uint32_t defaultMaterial = uint32_t(scene.materials.size());
  scene.materials.push_back(Material::unassignedDefault());

  // Local origin at the centre of the bounds of all vertices.
  Box3d bounds;
  const size_t nv = attrib.vertices.size() / 3;
  for (size_t i = 0; i < nv; ++i)
    bounds.extend(
        glm::dvec3(attrib.vertices[3 * i], attrib.vertices[3 * i + 1], attrib.vertices[3 * i + 2]));
  scene.origin = bounds.empty() ? glm::dvec3(0.0) : glm::floor(bounds.center());
  auto filePosition = [&](size_t idx) {
    return glm::dvec3(attrib.vertices[3 * idx], attrib.vertices[3 * idx + 1],
                      attrib.vertices[3 * idx + 2]);
  };
  // Finite in double is not enough: positions are stored as float relative
  // to the origin, and 1e308 (or a bounds centre that overflowed) is not.
  // One far vertex moves the origin so that others fail too: blame the
  // failing vertex farthest from zero in file coordinates.
  size_t worst = nv;
  double worstMagnitude = -1.0;
  for (size_t i = 0; i < nv; ++i) {
    const glm::dvec3 p = filePosition(i);
    const glm::vec3 local(p - scene.origin);
    if (std::isfinite(local.x) && std::isfinite(local.y) && std::isfinite(local.z)) continue;
    const double magnitude = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    if (magnitude > worstMagnitude) {
      worst = i;
      worstMagnitude = magnitude;
    }
  }
  if (worst < nv) {
    const glm::dvec3 p = filePosition(worst);
    throwInputError(
        "{}:{}: vertex {} ({}, {}, {}) is too far from the scene's local origin ({}, {}, {}) to "
        "store in single precision",
        displayName, lineOfVertex(objText, worst), worst + 1, p.x, p.y, p.z, scene.origin.x,
        scene.origin.y, scene.origin.z);
  }

  uint32_t faceId = 0;
  std::vector<glm::dvec3> polygon;
  std::vector<uint32_t> polygonLocal;
  std::vector<glm::uvec3> tris;
  // Per object: (position, texcoord) index pair -> local vertex. Corners that
  // share a position but not a texcoord become separate vertices.
  const size_t nt = attrib.texcoords.size() / 2;
  const bool withTexcoords = nt > 0;
  std::unordered_map<uint64_t, uint32_t> localOf;
  for (const auto& shape : shapes) {
    if (shape.mesh.num_face_vertices.empty()) continue;
    // Consecutive shapes with one name (an `o` split by `g` or `usemtl`) form one object.
    if (scene.objects.empty() || scene.objects.back().name != shape.name || shape.name.empty()) {
      // Vertex sharing is per object: forget the previous object's mapping.
      localOf.clear();
      scene.objects.emplace_back();
      scene.objects.back().name =
          shape.name.empty() ? fmt::format("object_{}", scene.objects.size() - 1) : shape.name;
    }
    Object* object = &scene.objects.back();
    TriangleMesh& mesh = object->mesh;
    size_t offset = 0;
    for (size_t f = 0; f < shape.mesh.num_face_vertices.size(); ++f, ++faceId) {
      const size_t n = shape.mesh.num_face_vertices[f];
      polygon.clear();
      polygonLocal.clear();
      for (size_t k = 0; k < n; ++k) {
        const int vi = shape.mesh.indices[offset + k].vertex_index;
        if (vi < 0 || size_t(vi) >= nv)
          throwInputError("{}:{}: face index out of range", displayName, scan.faceLines[faceId]);
        int ti = withTexcoords ? shape.mesh.indices[offset + k].texcoord_index : -1;
        if (ti >= 0 && size_t(ti) >= nt)
          throwInputError("{}:{}: texture coordinate index {} is out of range ({} in the file)",
                          displayName, scan.faceLines[faceId], ti + 1, nt);
        polygon.push_back(filePosition(size_t(vi)));
        const uint64_t key = uint64_t(vi) * (uint64_t(nt) + 1) + uint64_t(ti + 1);
        auto [it, inserted] = localOf.try_emplace(key, uint32_t(mesh.positions.size()));
        if (inserted) {
          mesh.positions.push_back(glm::vec3(polygon.back() - scene.origin));
          if (withTexcoords)
            mesh.texcoords.push_back(ti >= 0
                                         ? glm::vec2(float(attrib.texcoords[2 * size_t(ti)]),
                                                     float(attrib.texcoords[2 * size_t(ti) + 1]))
                                         : glm::vec2(0.0f));
        }
        polygonLocal.push_back(it->second);
      }
      offset += n;
      tris.clear();
      triangulatePolygon(polygon, tris);
      const int mat = f < shape.mesh.material_ids.size() ? shape.mesh.material_ids[f] : -1;
      const uint32_t material =
          mat >= 0 && size_t(mat) < defaultMaterial ? uint32_t(mat) : defaultMaterial;
      for (const glm::uvec3& t : tris) {
        mesh.triangles.emplace_back(polygonLocal[t.x], polygonLocal[t.y], polygonLocal[t.z]);
        mesh.faceIds.push_back(faceId);
        mesh.materials.push_back(material);
      }
    }
  }
  scene.faceCount = faceId;
  finalizeScene(scene);
  if (scene.diagnostics.degenerateTriangles > 0)
    spdlog::warn(
        "{}: {} degenerate triangles ({} with repeated vertices, {} of zero area) kept "
        "as visible geometry, never used as occluders",
        displayName, scene.diagnostics.degenerateTriangles,
        scene.diagnostics.repeatedVertexTriangles, scene.diagnostics.zeroAreaTriangles);
  return scene;
}

Scene loadObj(const std::filesystem::path& path, const SceneLimits& limits) {
  const std::string text = readSceneFile(path, limits);
  // The material library is optional: a missing one is a warning, not an error.
  std::string mtl;
  for (size_t at = text.find("mtllib"); at != std::string::npos; at = text.find("mtllib", at + 1)) {
    if (at != 0 && text[at - 1] != '\n') continue;
    std::vector<std::string_view> tokens;
    const size_t end = text.find('\n', at);
    tokenize(std::string_view(text).substr(at, end == std::string::npos ? end : end - at), tokens);
    if (tokens.size() < 2) break;
    const auto mtlPath = path.parent_path() / std::string(tokens[1]);
    std::error_code ec;
    if (std::filesystem::exists(mtlPath, ec)) {
      mtl = readSceneFile(mtlPath, limits);  // bounded: it may name /dev/zero
    } else {
      spdlog::warn("{}: material library {} not found; using default materials", path.string(),
                   mtlPath.string());
    }
    break;
  }
  Scene scene = loadObjFromMemory(text, path.string(), mtl, limits);
  scene.name = path.stem().string();
  scene.sources = {path};
  return scene;
}

}  // namespace vistream
