#include "server/impostor/impostor_database.h"

#include <flatbuffers/flatbuffers.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <atomic>
#include <mutex>

#include "common/core/error.h"
#include "common/core/timer.h"
#include "impostor_database_generated.h"
#include "protocol/geometry/byte_coding.h"
#include "protocol/impostor/impostor_codec.h"
#include "server/bake/bake_journal.h"
#include "server/bake/checked_file.h"
#include "server/bake/scene_grid_fields.h"

namespace vistream {
namespace {

constexpr std::array<char, 8> kImpostorDbMagic = {'V', 'S', 'I', 'M', 'P', 'D', 'B', '\0'};
constexpr std::array<char, 8> kImpostorJournalMagic = {'V', 'S', 'I', 'J', 'R', 'N', '2', '\0'};
constexpr uint64_t kMaxWhy = 4096, kMaxImpostorsPerCell = 4096;

}  // namespace

std::vector<uint8_t> encodeCellRecord(const CellRecord& record) {
  std::vector<uint8_t> out;
  const std::string why = record.why.substr(0, kMaxWhy);
  wire::putVarint(out, why.size());
  out.insert(out.end(), why.begin(), why.end());
  wire::putVarint(out, record.impostors.size());
  for (const StoredImpostor& s : record.impostors) {
    wire::putVarint(out, s.sector);
    wire::putVarint(out, s.band);
    const std::vector<uint8_t> faces = encodeFaceList(s.faces);
    wire::putVarint(out, s.faces.size());
    wire::putVarint(out, faces.size());
    out.insert(out.end(), faces.begin(), faces.end());
    wire::putVarint(out, s.bytes.size());
    out.insert(out.end(), s.bytes.begin(), s.bytes.end());
    wire::putVarint(out, s.points);
    wire::putVarint(out, s.screenPixels);
    wire::putVarint(out, s.coveredPixels);
    wire::putVarint(out, s.geometryBytes);
  }
  const std::vector<uint8_t> geometry = encodeFaceList(record.geometryFaces);
  wire::putVarint(out, record.geometryFaces.size());
  wire::putVarint(out, geometry.size());
  out.insert(out.end(), geometry.begin(), geometry.end());
  return out;
}

CellRecord decodeCellRecord(std::span<const uint8_t> bytes, uint32_t faceLimit) {
  wire::PayloadReader r(bytes);
  auto check = [&](auto value) {
    if (!value) throwInputError("cell record: {}", r.error());
    return *value;
  };
  CellRecord out;
  const uint64_t whyLength = check(r.varint("the reason's length", kMaxWhy));
  const auto why = check(r.bytes("the reason", whyLength));
  out.why.assign(why.begin(), why.end());
  const uint64_t count = check(r.varint("the impostor count", kMaxImpostorsPerCell));
  for (uint64_t k = 0; k < count; ++k) {
    StoredImpostor s;
    s.sector = uint32_t(check(r.varint("a sector", 1u << 16)));
    s.band = uint32_t(check(r.varint("a band", 1u << 16)));
    const uint64_t faceCount = check(r.varint("a face count", faceLimit));
    const uint64_t faceBytes = check(r.varint("a face list's length", r.remaining()));
    const auto faces = check(r.bytes("a face list", faceBytes));
    try {
      s.faces = decodeFaceList(faces.data(), faces.size(), uint32_t(faceCount), faceLimit);
    } catch (const InputError& e) {
      throwInputError("cell record: impostor {}: {}", k, e.what());
    }
    const uint64_t length = check(r.varint("an impostor's length", r.remaining()));
    const auto imp = check(r.bytes("an impostor", length));
    s.bytes.assign(imp.begin(), imp.end());
    s.points = check(r.varint("a point count", uint64_t(1) << 40));
    s.screenPixels = check(r.varint("a pixel count", uint64_t(1) << 40));
    s.coveredPixels = check(r.varint("a pixel count", uint64_t(1) << 40));
    s.geometryBytes = check(r.varint("a byte count", uint64_t(1) << 48));
    out.impostors.push_back(std::move(s));
  }
  const uint64_t geometryCount = check(r.varint("the geometry's face count", faceLimit));
  const uint64_t geometryBytes = check(r.varint("the geometry's length", r.remaining()));
  const auto geometry = check(r.bytes("the geometry's face list", geometryBytes));
  try {
    out.geometryFaces =
        decodeFaceList(geometry.data(), geometry.size(), uint32_t(geometryCount), faceLimit);
  } catch (const InputError& e) {
    throwInputError("cell record: the geometry's faces: {}", e.what());
  }
  if (r.remaining() != 0) throwInputError("cell record: {} bytes after its end", r.remaining());
  return out;
}

void writeImpostorDatabase(const std::filesystem::path& path, const ImpostorDatabaseHeader& header,
                           const std::map<uint32_t, std::vector<uint8_t>>& records) {
  flatbuffers::FlatBufferBuilder b(1 << 20);
  std::vector<flatbuffers::Offset<impdb::CellImpostors>> cells;
  cells.reserve(records.size());
  for (const auto& [index, record] : records)
    cells.push_back(impdb::CreateCellImpostors(b, index, b.CreateVector(record)));
  const PvsDatabaseHeader& h = header.pvs;
  const std::vector<double> origin = {h.origin.x, h.origin.y, h.origin.z};
  const std::vector<float> lo = {h.gridLo.x, h.gridLo.y, h.gridLo.z};
  const std::vector<float> size = {h.cellSize.x, h.cellSize.y, h.cellSize.z};
  const std::vector<int> dims = {h.dims.x, h.dims.y, h.dims.z};
  const auto root = impdb::CreateDatabaseDirect(
      b, kImpostorDbVersion, h.sceneName.c_str(), h.sceneFingerprint, h.sceneFaces, &origin, &lo,
      &size, &dims, h.method.c_str(), header.settings.c_str(), header.settingsFingerprint, &cells);
  impdb::FinishDatabaseBuffer(b, root);
  writeCheckedFile(path, kImpostorDbMagic, kImpostorDbVersion,
                   std::span(b.GetBufferPointer(), b.GetSize()));
}

ImpostorDatabase ImpostorDatabase::open(const std::filesystem::path& path) {
  ImpostorDatabase db;
  CheckedFile checked =
      openCheckedFile(path, kImpostorDbMagic, kImpostorDbVersion, "impostor database",
                      "; re-bake it with this build's vistream-pvs impostors");
  const std::string name = path.string();
  if (!checked.checksumOk())
    throwInputError("{}: checksum mismatch: the database is corrupt", name);
  db.path_ = path;
  db.file_ = std::move(checked.file);
  const std::span<const uint8_t> payload = db.file_.bytes().subspan(kCheckedFileHeaderBytes);
  flatbuffers::Verifier verifier(
      payload.data(), payload.size(), 64,
      flatbuffers::uoffset_t(std::min<uint64_t>(payload.size() / 4 + 1, 0xffffffffu)));
  if (!impdb::VerifyDatabaseBuffer(verifier))
    throwInputError("{}: database structure fails verification", name);
  const auto* root = impdb::GetDatabase(payload.data());
  PvsDatabaseHeader& h = db.header_.pvs;
  readSceneGridFields(root, name, h);
  h.method = root->pvs_method() ? root->pvs_method()->str() : "";
  db.header_.settings = root->settings() ? root->settings()->str() : "";
  db.header_.settingsFingerprint = root->settings_fingerprint();
  const uint64_t cellsTotal = uint64_t(h.dims.x) * uint64_t(h.dims.y) * uint64_t(h.dims.z);
  if (const auto* cells = root->cells()) {
    int64_t previous = -1;
    for (flatbuffers::uoffset_t n = 0; n < cells->size(); ++n) {
      const auto* c = cells->Get(n);
      if (int64_t(c->index()) <= previous || c->index() >= cellsTotal)
        throwInputError(
            "{}: cell entry {} has index {}: cell indices must be increasing and inside the grid "
            "of {} cells",
            name, n, c->index(), cellsTotal);
      previous = c->index();
      const std::span<const uint8_t> record =
          c->record() ? std::span(c->record()->data(), c->record()->size())
                      : std::span<const uint8_t>();
      try {
        decodeCellRecord(record, h.sceneFaces);
      } catch (const InputError& e) {
        throwInputError("{}: cell {}: {}", name, c->index(), e.what());
      }
      db.index_[c->index()] = record;
    }
  }
  return db;
}

std::vector<uint32_t> ImpostorDatabase::cellIndices() const {
  std::vector<uint32_t> out;
  for (const auto& [index, record] : index_) out.push_back(index);
  return out;
}

std::optional<CellRecord> ImpostorDatabase::cell(uint32_t linearIndex) const {
  const auto it = index_.find(linearIndex);
  if (it == index_.end()) return std::nullopt;
  try {
    return decodeCellRecord(it->second, header_.pvs.sceneFaces);
  } catch (const InputError& e) {
    spdlog::error(
        "{}: cell {}: {} (the file changed after it was opened?); treating the cell as "
        "not baked",
        path_.string(), linearIndex, e.what());
    return std::nullopt;
  }
}

ImpostorBakeReport bakeImpostorDatabase(const ImpostorWorld& world, const PvsDatabase& pvs,
                                        const ImpostorBakeOptions& options,
                                        const std::filesystem::path& out) {
  Stopwatch clock;
  const Scene& scene = world.scene();
  const PvsDatabaseHeader& ph = pvs.header();
  if (ph.sceneFingerprint != sceneFingerprint(scene) || ph.sceneFaces != scene.faceCount)
    throwInputError("{}: baked for scene '{}' ({} faces), not for this scene '{}' ({} faces)",
                    pvs.path().string(), ph.sceneName, ph.sceneFaces, scene.name, scene.faceCount);
  ImpostorDatabaseHeader header;
  header.pvs = ph;
  header.settings = options.settings;
  header.settingsFingerprint = fnv1a64(options.settings.data(), options.settings.size(),
                                       fnv1a64(&ph.sceneFingerprint, sizeof ph.sceneFingerprint));
  if (options.shardCount == 0 || options.shardIndex >= options.shardCount)
    throwInputError("shard {}/{} is not valid (expected i/n with 0 <= i < n)", options.shardIndex,
                    options.shardCount);
  const ViewCellGrid grid = ph.grid();
  std::vector<uint32_t> cells;
  size_t position = 0;
  for (uint32_t c : pvs.cellIndices())
    if (!options.region || grid.cellBox(grid.cellAt(c)).overlaps(*options.region))
      if (position++ % options.shardCount == options.shardIndex) cells.push_back(c);

  ImpostorBakeReport report;
  report.cells = cells.size();
  std::map<uint32_t, std::vector<uint8_t>> done;
  std::mutex doneMutex;
  BakeJournal journal(out.string() + ".journal", kImpostorJournalMagic, header.settingsFingerprint,
                      [&](const JournalRecordView& r) -> std::string {
                        if (r.index >= grid.cellCount())
                          return fmt::format("cell index {} is outside the grid of {} cells",
                                             r.index, grid.cellCount());
                        try {
                          decodeCellRecord(r.payload, ph.sceneFaces);
                        } catch (const InputError& e) {
                          return e.what();
                        }
                        done[r.index].assign(r.payload.begin(), r.payload.end());
                        return {};
                      });
  std::vector<uint32_t> pending;
  for (uint32_t c : cells)
    if (!done.count(c)) pending.push_back(c);
  report.resumedCells = cells.size() - pending.size();
  std::atomic<size_t> progress{report.resumedCells};
  if (options.progress) options.progress(progress.load(), cells.size());

  std::optional<tbb::global_control> limit;
  if (options.threads > 0)
    limit.emplace(tbb::global_control::max_allowed_parallelism, options.threads);
  // Cells one after another, each bake parallel inside (its impostors are
  // the work; a cell holds a few).
  for (uint32_t c : pending) {
    const std::optional<std::vector<uint32_t>> faces = pvs.cell(c);
    if (!faces) throwInputError("{}: cell {} cannot be read", pvs.path().string(), c);
    const CellImpostors r =
        world.bakeCell(grid.cellBox(grid.cellAt(c)), *faces, options.placement, options.impostor);
    CellRecord record;
    record.why = r.placement.why;
    record.geometryFaces = r.geometryFaces;
    for (size_t i = 0; i < r.impostors.size(); ++i) {
      const ImpostorSite& site = r.placement.sites[r.siteOf[i]];
      StoredImpostor s;
      s.sector = site.sector;
      s.band = site.band;
      s.faces = r.replacedFaces[i];
      s.bytes = wire::encodeImpostor(r.impostors[i]);
      s.points = r.stats[i].points;
      s.screenPixels = r.stats[i].screenPixels;
      s.coveredPixels = r.stats[i].coveredPixels;
      s.geometryBytes = r.geometryBytes[i];
      record.impostors.push_back(std::move(s));
    }
    std::vector<uint8_t> bytes = encodeCellRecord(record);
    journal.append(c, uint32_t(record.impostors.size()), bytes);
    {
      std::lock_guard lock(doneMutex);
      done[c] = std::move(bytes);
    }
    ++report.computedCells;
    const size_t p = ++progress;
    if (options.progress) options.progress(p, cells.size());
  }
  std::map<uint32_t, std::vector<uint8_t>> records;
  for (uint32_t c : cells) {
    const CellRecord record = decodeCellRecord(done.at(c), ph.sceneFaces);
    report.cellsWithImpostors += !record.impostors.empty();
    report.impostors += record.impostors.size();
    report.geometryFaces += record.geometryFaces.size();
    for (const StoredImpostor& s : record.impostors) {
      report.points += s.points;
      report.bytes += s.bytes.size();
      report.geometryBytes += s.geometryBytes;
    }
    records[c] = std::move(done.at(c));
  }
  writeImpostorDatabase(out, header, records);
  journal.remove();
  report.timeMs = clock.ms();
  return report;
}

void mergeImpostorDatabases(const std::vector<std::filesystem::path>& inputs,
                            const std::filesystem::path& out) {
  if (inputs.empty()) throwInputError("impostor-merge needs at least one database");
  ImpostorDatabaseHeader header;
  std::map<uint32_t, std::vector<uint8_t>> records;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const ImpostorDatabase db = ImpostorDatabase::open(inputs[i]);
    if (i == 0) {
      header = db.header();
    } else if (!header.pvs.compatible(db.header().pvs) ||
               header.settingsFingerprint != db.header().settingsFingerprint) {
      throwInputError("{}: baked from another PVS database or with other settings than {}",
                      inputs[i].string(), inputs[0].string());
    }
    for (uint32_t c : db.cellIndices()) {
      const std::optional<CellRecord> record = db.cell(c);
      if (!record) throwInputError("{}: cell {} cannot be read", inputs[i].string(), c);
      std::vector<uint8_t> bytes = encodeCellRecord(*record);
      const auto [it, inserted] = records.try_emplace(c, bytes);
      if (!inserted && it->second != bytes)
        throwInputError("{}: cell {} differs from the same cell in an earlier input",
                        inputs[i].string(), c);
    }
  }
  writeImpostorDatabase(out, header, records);
}

}  // namespace vistream
