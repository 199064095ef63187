#include "common/scene/scene_loader.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <limits>

#include "common/core/error.h"
#include "common/scene/manifest.h"

namespace vistream {

Scene loadScene(const std::filesystem::path& path, const SceneLimits& limits) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".obj") return loadObj(path, limits);
  if (ext == ".gltf" || ext == ".glb") return loadGltf(path, limits);
  if (ext == ".json") return loadManifest(path, limits);
  throwInputError("{}: unknown scene format '{}' (expected .obj, .gltf, .glb or a .json manifest)",
                  path.string(), ext);
}

std::string readSceneFile(const std::filesystem::path& path, const SceneLimits& limits) {
  namespace fs = std::filesystem;
  const std::string file = path.string();
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) throwInputError("{}: no such file", file);
  if (ec) throwInputError("{}: {}", file, ec.message());
  if (fs::is_directory(status)) throwInputError("{}: is a directory, expected a file", file);
  // A FIFO or a device such as /dev/zero has no size to check and may never end.
  if (!fs::is_regular_file(status)) throwInputError("{}: is not a regular file", file);
  const uintmax_t size = fs::file_size(path, ec);
  if (ec)
    throwInputError(InputErrorCode::BadFile, "{}: cannot read its size: {}", file, ec.message());
  if (size > limits.maxFileBytes)
    throwInputError("{}: the file has {} bytes, more than the limit of {} bytes for a scene file",
                    file, size, limits.maxFileBytes);
  std::ifstream in(path, std::ios::binary);
  if (!in) throwInputError(InputErrorCode::BadFile, "{}: cannot open for reading", file);
  std::string bytes(size_t(size), '\0');
  in.read(bytes.data(), std::streamsize(size));
  if (in.gcount() != std::streamsize(size))
    throwInputError("{}: read error ({} of {} bytes read)", file, in.gcount(), size);
  return bytes;
}

void checkJsonNesting(std::string_view json, const std::string& name) {
  size_t depth = 0;
  size_t line = 1;
  bool inString = false, escaped = false;
  for (const char c : json) {
    if (c == '\n') ++line;
    if (inString) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        inString = false;
    } else if (c == '"') {
      inString = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonNesting)
        throwInputError("{}:{}: JSON nesting depth exceeds the limit of {} levels", name, line,
                        kMaxJsonNesting);
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
}

uint64_t triangleLimit(const SceneLimits& limits) {
  return std::min<uint64_t>(limits.maxTriangles, std::numeric_limits<uint32_t>::max());
}

uint64_t vertexLimit(const SceneLimits& limits) {
  return std::min<uint64_t>(3 * triangleLimit(limits), std::numeric_limits<int32_t>::max());
}

void throwSceneLimit(const std::string& file, uint64_t found, uint64_t limit,
                     const std::string& unit) {
  if (unit == "triangles")
    throw SceneLimitError(fmt::format("{}: {} triangles, more than the limit of {}; raise it with "
                                      "--max-scene-triangles",
                                      file, found, limit),
                          found, limit);
  throw SceneLimitError(fmt::format("{}: {} {}, more than the limit of {} (3 per triangle of the "
                                    "triangle limit); raise it with --max-scene-triangles",
                                    file, found, unit, limit),
                        found, limit);
}

}  // namespace vistream
