#include "server/visibility/pvs_database.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <fstream>

#include "common/core/error.h"
#include "pvs_database_generated.h"

namespace vistream {
namespace {

constexpr char kMagic[8] = {'V', 'S', 'P', 'V', 'S', 'D', 'B', '\0'};
constexpr size_t kHeaderBytes = 32;

uint64_t fnv1a(const uint8_t* data, size_t size, uint64_t h = 1469598103934665603ull) {
  for (size_t i = 0; i < size; ++i) {
    h ^= data[i];
    h *= 1099511628211ull;
  }
  return h;
}

template <typename T>
uint64_t fnvValue(uint64_t h, const T& v) {
  return fnv1a(reinterpret_cast<const uint8_t*>(&v), sizeof(T), h);
}

void putU32(uint8_t* p, uint32_t v) { for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i)); }
void putU64(uint8_t* p, uint64_t v) { for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i)); }
uint32_t getU32(const uint8_t* p) { uint32_t v = 0; for (int i = 0; i < 4; ++i) v |= uint32_t(p[i]) << (8 * i); return v; }
uint64_t getU64(const uint8_t* p) { uint64_t v = 0; for (int i = 0; i < 8; ++i) v |= uint64_t(p[i]) << (8 * i); return v; }

}  // namespace

uint64_t sceneFingerprint(const Scene& scene) {
  uint64_t h = fnvValue(1469598103934665603ull, scene.faceCount);
  h = fnvValue(h, uint64_t(scene.objects.size()));
  for (const Object& o : scene.objects) {
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      h = fnvValue(h, o.mesh.faceIds[t]);
      for (int k = 0; k < 3; ++k) {
        // Positions in file coordinates, so the fingerprint does not depend
        // on where the loader put the local origin.
        const glm::dvec3 p = scene.toFile(o.mesh.positions[o.mesh.triangles[t][k]]);
        const glm::vec3 pf(p);
        h = fnvValue(h, pf.x);
        h = fnvValue(h, pf.y);
        h = fnvValue(h, pf.z);
      }
    }
  }
  return h;
}

ViewCellGrid PvsDatabaseHeader::grid() const {
  return ViewCellGrid(Box3f(gridLo, gridLo + cellSize * glm::vec3(dims)), cellSize);
}

bool PvsDatabaseHeader::compatible(const PvsDatabaseHeader& o) const {
  return sceneFingerprint == o.sceneFingerprint && sceneFaces == o.sceneFaces && gridLo == o.gridLo &&
         cellSize == o.cellSize && dims == o.dims && method == o.method;
}

std::vector<uint8_t> encodeFaceList(const std::vector<uint32_t>& faces) {
  std::vector<uint8_t> out;
  out.reserve(faces.size() * 2);
  uint32_t prev = 0;
  for (size_t i = 0; i < faces.size(); ++i) {
    uint32_t delta = i == 0 ? faces[0] : faces[i] - prev;
    prev = faces[i];
    do {
      uint8_t byte = delta & 0x7f;
      delta >>= 7;
      out.push_back(delta ? byte | 0x80 : byte);
    } while (delta);
  }
  return out;
}

std::vector<uint32_t> decodeFaceList(const uint8_t* data, size_t size, uint32_t expected) {
  std::vector<uint32_t> out;
  if (expected > size) throwInputError("face list claims {} faces in {} bytes", expected, size);
  out.reserve(expected);
  size_t pos = 0;
  uint64_t prev = 0;
  while (pos < size) {
    uint64_t value = 0;
    int shift = 0;
    while (true) {
      if (pos >= size || shift > 28) throwInputError("face list has a malformed varint at byte {}", pos);
      const uint8_t b = data[pos++];
      value |= uint64_t(b & 0x7f) << shift;
      if (!(b & 0x80)) break;
      shift += 7;
    }
    const uint64_t face = out.empty() ? value : prev + value;
    if (face > 0xffffffffull || (!out.empty() && value == 0))
      throwInputError("face list is not strictly increasing at entry {}", out.size());
    out.push_back(uint32_t(face));
    prev = face;
  }
  if (out.size() != expected) throwInputError("face list holds {} faces, header says {}", out.size(), expected);
  return out;
}

void writePvsDatabase(const std::filesystem::path& path, const PvsDatabaseHeader& h,
                      const std::map<uint32_t, std::vector<uint32_t>>& cells) {
  flatbuffers::FlatBufferBuilder b(1 << 20);
  std::vector<flatbuffers::Offset<pvsdb::CellPvs>> cellOffsets;
  cellOffsets.reserve(cells.size());
  for (const auto& [index, faces] : cells) {
    const auto bytes = encodeFaceList(faces);
    cellOffsets.push_back(pvsdb::CreateCellPvs(b, index, uint32_t(faces.size()), b.CreateVector(bytes)));
  }
  const std::vector<double> origin = {h.origin.x, h.origin.y, h.origin.z};
  const std::vector<float> lo = {h.gridLo.x, h.gridLo.y, h.gridLo.z};
  const std::vector<float> size = {h.cellSize.x, h.cellSize.y, h.cellSize.z};
  const std::vector<int> dims = {h.dims.x, h.dims.y, h.dims.z};
  const auto root = pvsdb::CreateDatabaseDirect(b, kPvsDbVersion, h.sceneName.c_str(), h.sceneFingerprint,
                                                h.sceneFaces, &origin, &lo, &size, &dims, h.method.c_str(),
                                                &cellOffsets);
  pvsdb::FinishDatabaseBuffer(b, root);

  uint8_t header[kHeaderBytes] = {};
  std::memcpy(header, kMagic, 8);
  putU32(header + 8, kPvsDbVersion);
  putU64(header + 16, b.GetSize());
  putU64(header + 24, fnv1a(b.GetBufferPointer(), b.GetSize()));

  const std::filesystem::path tmp = path.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) throwInputError("{}: cannot open for writing: {}", tmp.string(), std::strerror(errno));
  auto writeAll = [&](const uint8_t* p, size_t n) {
    while (n > 0) {
      const ssize_t w = ::write(fd, p, n);
      if (w < 0) {
        if (errno == EINTR) continue;
        const std::string err = std::strerror(errno);
        ::close(fd);
        throwInputError("{}: write failed: {}", tmp.string(), err);
      }
      p += w;
      n -= size_t(w);
    }
  };
  writeAll(header, kHeaderBytes);
  writeAll(b.GetBufferPointer(), b.GetSize());
  if (::fsync(fd) != 0 || ::close(fd) != 0)
    throwInputError("{}: cannot flush to disk: {}", tmp.string(), std::strerror(errno));
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throwInputError("{}: cannot rename into place: {}", path.string(), ec.message());
}

PvsDatabase::PvsDatabase(PvsDatabase&& o) noexcept { *this = std::move(o); }

PvsDatabase& PvsDatabase::operator=(PvsDatabase&& o) noexcept {
  if (this != &o) {
    if (map_) ::munmap(const_cast<uint8_t*>(map_), mapSize_);
    path_ = std::move(o.path_);
    map_ = std::exchange(o.map_, nullptr);
    mapSize_ = std::exchange(o.mapSize_, 0);
    root_ = std::exchange(o.root_, nullptr);
    header_ = std::move(o.header_);
  }
  return *this;
}

PvsDatabase::~PvsDatabase() {
  if (map_) ::munmap(const_cast<uint8_t*>(map_), mapSize_);
}

PvsDatabase PvsDatabase::open(const std::filesystem::path& path) {
  const std::string name = path.string();
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) throwInputError("{}: cannot open PVS database: {}", name, std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throwInputError("{}: not a regular file", name);
  }
  const size_t size = size_t(st.st_size);
  if (size < kHeaderBytes) {
    ::close(fd);
    throwInputError("{}: not a PVS database (only {} bytes)", name, size);
  }
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  ::close(fd);
  if (map == MAP_FAILED) throwInputError("{}: cannot map: {}", name, std::strerror(errno));
  PvsDatabase db;
  db.path_ = path;
  db.map_ = static_cast<const uint8_t*>(map);
  db.mapSize_ = size;
  const uint8_t* p = db.map_;
  if (std::memcmp(p, kMagic, 8) != 0) throwInputError("{}: not a PVS database (bad magic)", name);
  const uint32_t version = getU32(p + 8);
  if (version != kPvsDbVersion)
    throwInputError("{}: PVS database format version {} is not supported (this build reads {})", name, version,
                    kPvsDbVersion);
  const uint64_t payload = getU64(p + 16);
  if (payload != size - kHeaderBytes)
    throwInputError("{}: truncated or padded: header says {} payload bytes, file has {}", name, payload,
                    size - kHeaderBytes);
  if (fnv1a(p + kHeaderBytes, payload) != getU64(p + 24))
    throwInputError("{}: checksum mismatch: the database is corrupt", name);
  flatbuffers::Verifier verifier(p + kHeaderBytes, payload);
  if (!pvsdb::VerifyDatabaseBuffer(verifier)) throwInputError("{}: database structure fails verification", name);
  const auto* root = pvsdb::GetDatabase(p + kHeaderBytes);
  db.root_ = root;
  auto vec3 = [&](const auto* v, const char* what) {
    if (!v || v->size() != 3) throwInputError("{}: field '{}' must hold 3 values", name, what);
    return v;
  };
  PvsDatabaseHeader& h = db.header_;
  h.sceneName = root->scene_name() ? root->scene_name()->str() : "";
  h.sceneFingerprint = root->scene_fingerprint();
  h.sceneFaces = root->scene_faces();
  const auto* o = vec3(root->origin(), "origin");
  h.origin = {o->Get(0), o->Get(1), o->Get(2)};
  const auto* lo = vec3(root->grid_lo(), "grid_lo");
  h.gridLo = {lo->Get(0), lo->Get(1), lo->Get(2)};
  const auto* cs = vec3(root->cell_size(), "cell_size");
  h.cellSize = {cs->Get(0), cs->Get(1), cs->Get(2)};
  const auto* d = vec3(root->dims(), "dims");
  h.dims = {d->Get(0), d->Get(1), d->Get(2)};
  h.method = root->method() ? root->method()->str() : "";
  for (int a = 0; a < 3; ++a)
    if (!(h.cellSize[a] > 0.0f) || h.dims[a] <= 0 || h.dims[a] > (1 << 20))
      throwInputError("{}: invalid grid (cell size and dims must be positive)", name);
  const uint64_t cellsTotal = uint64_t(h.dims.x) * uint64_t(h.dims.y) * uint64_t(h.dims.z);
  if (const auto* cells = root->cells()) {
    int64_t prev = -1;
    for (const auto* c : *cells) {
      if (int64_t(c->index()) <= prev || c->index() >= cellsTotal)
        throwInputError("{}: cell indices must be increasing and inside the grid", name);
      prev = c->index();
    }
  }
  return db;
}

size_t PvsDatabase::cellCount() const {
  const auto* cells = static_cast<const pvsdb::Database*>(root_)->cells();
  return cells ? cells->size() : 0;
}

std::vector<uint32_t> PvsDatabase::cellIndices() const {
  std::vector<uint32_t> out;
  if (const auto* cells = static_cast<const pvsdb::Database*>(root_)->cells())
    for (const auto* c : *cells) out.push_back(c->index());
  return out;
}

std::optional<std::vector<uint32_t>> PvsDatabase::cell(uint32_t linearIndex) const {
  const auto* cells = static_cast<const pvsdb::Database*>(root_)->cells();
  if (!cells) return std::nullopt;
  const auto* c = cells->LookupByKey(linearIndex);
  if (!c) return std::nullopt;
  const auto* bytes = c->faces();
  std::vector<uint32_t> faces =
      bytes ? decodeFaceList(bytes->data(), bytes->size(), c->face_count()) : std::vector<uint32_t>{};
  for (uint32_t f : faces)
    if (f >= header_.sceneFaces)
      throwInputError("{}: cell {} lists face {} beyond the scene's {} faces", path_.string(), linearIndex, f,
                      header_.sceneFaces);
  return faces;
}

}  // namespace vistream
