#include "server/visibility/pvs_database.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <fstream>
#include <limits>

#include "common/core/error.h"
#include "pvs_database_generated.h"
#include "server/bake/checked_file.h"
#include "server/bake/scene_grid_fields.h"

namespace vistream {
namespace {

constexpr std::array<char, 8> kPvsMagic = {'V', 'S', 'P', 'V', 'S', 'D', 'B', '\0'};
constexpr size_t kHeaderBytes = kCheckedFileHeaderBytes;

template <typename T>
uint64_t fnvValue(uint64_t h, const T& v) {
  return fnv1a64(&v, sizeof(T), h);
}

// Reads one LEB128 varint of at most 5 bytes (a 32-bit value needs no more)
// at `pos`; false if it is cut off or longer.
inline bool readVarint(const uint8_t* data, size_t size, size_t& pos, uint64_t& value) {
  value = data[pos++];
  if (!(value & 0x80)) return true;
  value &= 0x7f;
  for (int shift = 7; pos < size && shift <= 28; shift += 7) {
    const uint8_t b = data[pos++];
    value |= uint64_t(b & 0x7f) << shift;
    if (!(b & 0x80)) return true;
  }
  return false;
}

// Decodes a face list, calling emit(face) for each face, without allocating.
// Returns what is wrong (a phrase starting "face list"), or nothing if the
// list is `expected` well-formed varints of at most 5 bytes giving strictly
// increasing IDs below `faceLimit` (<= 2^32). The one decoder behind
// decodeFaceList, open()'s validation and cell(), so they cannot disagree.
template <typename Emit>
std::optional<std::string> scanFaceList(const uint8_t* data, size_t size, uint32_t expected,
                                        uint64_t faceLimit, Emit&& emit) {
  faceLimit = std::min(faceLimit, uint64_t(1) << 32);  // face IDs are 32-bit
  // Every face takes at least one byte: this also bounds the caller's reserve().
  if (expected > size) return fmt::format("face list claims {} faces in {} bytes", expected, size);
  size_t pos = 0;
  uint32_t count = 0;
  uint64_t prev = 0;
  while (pos < size) {
    const size_t start = pos;
    uint64_t value = 0;
    if (!readVarint(data, size, pos, value))
      return fmt::format("face list has a malformed varint at byte {}", start);
    if (count > 0 && value == 0)
      return fmt::format("face list is not strictly increasing at entry {} (face {} repeated)",
                         count, prev);
    const uint64_t face = count == 0 ? value : prev + value;  // < 2^32 + 2^35: no overflow
    if (face >= faceLimit)
      return fmt::format("face list entry {} is face {}, not below the face count {}", count, face,
                         faceLimit);
    emit(uint32_t(face));
    prev = face;
    ++count;
  }
  if (count != expected)
    return fmt::format("face list holds {} faces, header says {}", count, expected);
  return std::nullopt;
}

glm::ivec3 cellOfIndex(uint32_t linear, const glm::ivec3& dims) {
  const uint64_t row = uint64_t(dims.x), layer = row * uint64_t(dims.y);
  return {int(linear % row), int(linear / row % uint64_t(dims.y)), int(linear / layer)};
}

}  // namespace

uint64_t fnv1a64(const void* data, size_t size, uint64_t h) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
  return h;
}

uint64_t sceneFingerprint(const Scene& scene) {
  uint64_t h = fnvValue(kFnv1a64OffsetBasis, scene.faceCount);
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
  return sceneFingerprint == o.sceneFingerprint && sceneFaces == o.sceneFaces &&
         gridLo == o.gridLo && cellSize == o.cellSize && dims == o.dims && method == o.method;
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

std::vector<uint32_t> decodeFaceList(const uint8_t* data, size_t size, uint32_t expected,
                                     uint64_t faceLimit) {
  std::vector<uint32_t> out;
  if (expected <= size) out.reserve(expected);
  if (auto fault =
          scanFaceList(data, size, expected, faceLimit, [&](uint32_t f) { out.push_back(f); }))
    throw InputError(*fault);
  return out;
}

void writePvsDatabase(const std::filesystem::path& path, const PvsDatabaseHeader& h,
                      const std::map<uint32_t, std::vector<uint32_t>>& cells) {
  flatbuffers::FlatBufferBuilder b(1 << 20);
  std::vector<flatbuffers::Offset<pvsdb::CellPvs>> cellOffsets;
  cellOffsets.reserve(cells.size());
  for (const auto& [index, faces] : cells) {
    const auto bytes = encodeFaceList(faces);
    cellOffsets.push_back(
        pvsdb::CreateCellPvs(b, index, uint32_t(faces.size()), b.CreateVector(bytes)));
  }
  const std::vector<double> origin = {h.origin.x, h.origin.y, h.origin.z};
  const std::vector<float> lo = {h.gridLo.x, h.gridLo.y, h.gridLo.z};
  const std::vector<float> size = {h.cellSize.x, h.cellSize.y, h.cellSize.z};
  const std::vector<int> dims = {h.dims.x, h.dims.y, h.dims.z};
  const auto root = pvsdb::CreateDatabaseDirect(b, kPvsDbVersion, h.sceneName.c_str(),
                                                h.sceneFingerprint, h.sceneFaces, &origin, &lo,
                                                &size, &dims, h.method.c_str(), &cellOffsets);
  pvsdb::FinishDatabaseBuffer(b, root);

  writeCheckedFile(path, kPvsMagic, kPvsDbVersion, std::span(b.GetBufferPointer(), b.GetSize()));
}

PvsDatabase PvsDatabase::open(const std::filesystem::path& path) {
  PvsDatabase db;
  CheckedFile checked = openCheckedFile(
      path, kPvsMagic, kPvsDbVersion, "PVS database",
      "; re-bake it with this build's vistream-pvs bake (version 1 seeded its checksum with a "
      "wrong FNV offset basis)");
  db.path_ = path;
  db.checksum_ = checked.checksum;
  db.file_ = std::move(checked.file);
  const std::string name = path.string();
  // The checksum and the structure (verifier, header fields, every cell's
  // face list) are two passes over the payload of about the same length, so
  // they run side by side. The verifier makes reading the payload safe
  // whatever its bytes; a checksum mismatch is reported first, as it
  // explains any other fault.
  bool checksumOk = false;
  std::optional<std::string> fault;
  tbb::parallel_invoke(
      [&] {
        const auto p = db.file_.bytes().subspan(kCheckedFileHeaderBytes);
        checksumOk = fnv1a64(p.data(), p.size()) == db.checksum_;
      },
      [&] {
        try {
          db.readPayload();
        } catch (const InputError& e) {
          fault = e.what();
        }
      });
  if (!checksumOk) throwInputError("{}: checksum mismatch: the database is corrupt", name);
  if (fault) throw InputError(*fault);
  return db;
}

void PvsDatabase::readPayload() {
  const std::string name = path_.string();
  const uint8_t* payload = file_.data() + kHeaderBytes;
  const size_t payloadBytes = file_.size() - kHeaderBytes;
  // The verifier's default cap of 10^6 tables would refuse big bakes (one
  // table per cell); every table takes at least 4 bytes, so this cap still
  // bounds verification by the file's size.
  flatbuffers::Verifier verifier(
      payload, payloadBytes, 64,
      flatbuffers::uoffset_t(std::min<uint64_t>(payloadBytes / 4 + 1, 0xffffffffu)));
  if (!pvsdb::VerifyDatabaseBuffer(verifier))
    throwInputError("{}: database structure fails verification", name);
  const auto* root = pvsdb::GetDatabase(payload);
  root_ = root;
  PvsDatabaseHeader& h = header_;
  readSceneGridFields(root, name, h);
  h.method = root->method() ? root->method()->str() : "";
  const uint64_t cellsTotal = uint64_t(h.dims.x) * uint64_t(h.dims.y) * uint64_t(h.dims.z);
  const auto* cells = root->cells();
  if (!cells) return;
  int64_t prev = -1;
  for (flatbuffers::uoffset_t n = 0; n < cells->size(); ++n) {
    const uint32_t index = cells->Get(n)->index();
    if (int64_t(index) <= prev || index >= cellsTotal)
      throwInputError(
          "{}: cell entry {} has index {}: cell indices must be increasing and inside the grid of "
          "{} "
          "cells",
          name, n, index, cellsTotal);
    prev = index;
  }
  // Every face list is decoded here, once, so that cell() cannot fail later
  // on a worker thread, and a bad file is refused when the server starts,
  // not when a client first walks into the cell. In parallel over cells; the
  // first bad cell (in file order) is the one reported.
  auto listFault = [&](flatbuffers::uoffset_t n) {
    const auto* c = cells->Get(n);
    const auto* bytes = c->faces();
    return scanFaceList(bytes ? bytes->data() : nullptr, bytes ? bytes->size() : 0, c->face_count(),
                        h.sceneFaces, [](uint32_t) {});
  };
  using Range = tbb::blocked_range<flatbuffers::uoffset_t>;
  constexpr flatbuffers::uoffset_t kNone = std::numeric_limits<flatbuffers::uoffset_t>::max();
  const flatbuffers::uoffset_t firstBad = tbb::parallel_reduce(
      Range(0, cells->size(), 1024), kNone,
      [&](const Range& r, flatbuffers::uoffset_t found) {
        for (flatbuffers::uoffset_t n = r.begin(); n < r.end() && n < found; ++n)
          if (listFault(n)) return n;
        return found;
      },
      [](flatbuffers::uoffset_t a, flatbuffers::uoffset_t b) { return std::min(a, b); });
  if (firstBad != kNone) {
    const uint32_t index = cells->Get(firstBad)->index();
    const glm::ivec3 ijk = cellOfIndex(index, h.dims);
    throwInputError("{}: cell {} (i,j,k {},{},{}): {}", name, index, ijk.x, ijk.y, ijk.z,
                    *listFault(firstBad));
  }
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
  std::vector<uint32_t> faces;
  faces.reserve(bytes ? std::min<size_t>(c->face_count(), bytes->size()) : 0);
  // open() decoded this list with the same function; it can only fail if the
  // file changed under the mapping since.
  if (auto fault =
          scanFaceList(bytes ? bytes->data() : nullptr, bytes ? bytes->size() : 0, c->face_count(),
                       header_.sceneFaces, [&](uint32_t f) { faces.push_back(f); })) {
    const glm::ivec3 ijk = cellOfIndex(linearIndex, header_.dims);
    spdlog::error(
        "{}: cell {} (i,j,k {},{},{}): {} (the file changed after it was opened?); treating the "
        "cell "
        "as not baked",
        path_.string(), linearIndex, ijk.x, ijk.y, ijk.z, *fault);
    return std::nullopt;
  }
  return faces;
}

}  // namespace vistream
