#include "server/impostor/impostor_database.h"

#include <flatbuffers/flatbuffers.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <atomic>
#include <mutex>

#include "common/core/error.h"
#include "common/core/ivec_less.h"
#include "common/core/timer.h"
#include "impostor_database_generated.h"
#include "protocol/geometry/byte_coding.h"
#include "protocol/impostor/impostor_codec.h"
#include "server/bake/bake_journal.h"
#include "server/bake/checked_file.h"
#include "server/bake/scene_grid_fields.h"
#include "server/impostor/view_cell_groups.h"

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
  for (int a = 0; a < 3; ++a) wire::putVarint(out, uint64_t(std::max(0, record.viewLo[a])));
  for (int a = 0; a < 3; ++a) wire::putVarint(out, uint64_t(std::max(0, record.viewHi[a])));
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
  for (int a = 0; a < 3; ++a)
    out.viewLo[a] = int(check(r.varint("the view cell's first cell", (1u << 31) - 1)));
  for (int a = 0; a < 3; ++a)
    out.viewHi[a] = int(check(r.varint("the view cell's last cell", (1u << 31) - 1)));
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
  const ViewCellGrid grid = h.grid();
  std::map<uint32_t, std::pair<glm::ivec3, glm::ivec3>> ranges;  // cell -> its view cell
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
      CellRecord decoded;
      try {
        decoded = decodeCellRecord(record, h.sceneFaces);
      } catch (const InputError& e) {
        throwInputError("{}: cell {}: {}", name, c->index(), e.what());
      }
      db.index_[c->index()] = record;
      ranges.emplace(c->index(), std::make_pair(decoded.viewLo, decoded.viewHi));
      if (c->index() != grid.linearIndex(decoded.viewLo) &&
          (!decoded.impostors.empty() || !decoded.geometryFaces.empty()))
        throwInputError(
            "{}: cell {}: holds impostors or faces, but its view cell's leader is another cell",
            name, c->index());
    }
  }
  // Each cell's view cell: inside the grid, holding the cell, its leader
  // present with the same range.
  for (const auto& [index, range] : ranges) {
    const auto& [lo, hi] = range;
    const glm::ivec3 cell = grid.cellAt(index);
    if (!grid.contains(lo) || !grid.contains(hi) || !cellWithin(cell, lo, hi))
      throwInputError("{}: cell {}: its view cell ({}, {}, {})-({}, {}, {}) does not hold it", name,
                      index, lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
    const uint32_t leader = uint32_t(grid.linearIndex(lo));
    const auto it = ranges.find(leader);
    if (it == ranges.end() || it->second != range)
      throwInputError("{}: cell {}: its view cell's leader, cell {}, is {}", name, index, leader,
                      it == ranges.end() ? "missing" : "of another view cell");
    db.leaders_[index] = leader;
  }
  return db;
}

std::optional<uint32_t> ImpostorDatabase::viewCellOf(uint32_t linearIndex) const {
  const auto it = leaders_.find(linearIndex);
  if (it == leaders_.end()) return std::nullopt;
  return it->second;
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
  std::vector<uint32_t> regionCells;
  for (uint32_t c : pvs.cellIndices())
    if (!options.region || grid.cellBox(grid.cellAt(c)).overlaps(*options.region))
      regionCells.push_back(c);
  // View cells first (so a shard bakes whole ones), then this shard's.
  std::vector<ViewCellGroup> groups;
  {
    std::vector<ViewCellGroup> all = mergeViewCells(grid, regionCells, options.mergeCells);
    for (size_t g = 0; g < all.size(); ++g)
      if (g % options.shardCount == options.shardIndex) groups.push_back(std::move(all[g]));
  }
  std::vector<uint32_t> cells;
  for (const ViewCellGroup& g : groups)
    cells.insert(cells.end(), g.members.begin(), g.members.end());
  std::sort(cells.begin(), cells.end());

  ImpostorBakeReport report;
  report.cells = cells.size();
  report.viewCells = groups.size();
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
  // A view cell is baked again unless every one of its cells was journalled.
  std::vector<const ViewCellGroup*> pending;
  for (const ViewCellGroup& g : groups)
    if (!std::all_of(g.members.begin(), g.members.end(), [&](uint32_t c) { return done.count(c); }))
      pending.push_back(&g);
  size_t pendingCells = 0;
  for (const ViewCellGroup* g : pending) pendingCells += g->members.size();
  report.resumedCells = cells.size() - pendingCells;
  std::atomic<size_t> progress{report.resumedCells};
  if (options.progress) options.progress(progress.load(), cells.size());

  std::optional<tbb::global_control> limit;
  if (options.threads > 0)
    limit.emplace(tbb::global_control::max_allowed_parallelism, options.threads);
  // View cells one after another, each bake parallel inside (its impostors
  // are the work; a view cell holds a few).
  for (const ViewCellGroup* g : pending) {
    // The view cell's PVS: the union of its cells' (each is conservative
    // for its cell, so the union is for theirs).
    std::vector<uint32_t> faces;
    for (uint32_t c : g->members) {
      const std::optional<std::vector<uint32_t>> cellFaces = pvs.cell(c);
      if (!cellFaces) throwInputError("{}: cell {} cannot be read", pvs.path().string(), c);
      std::vector<uint32_t> merged;
      std::set_union(faces.begin(), faces.end(), cellFaces->begin(), cellFaces->end(),
                     std::back_inserter(merged));
      faces = std::move(merged);
    }
    const CellImpostors r =
        world.bakeCell(viewCellBox(grid, g->lo, g->hi), faces, options.placement, options.impostor);
    spdlog::debug(
        "view cell ({}, {}, {})-({}, {}, {}): {} cells, {} PVS faces, {} impostors, {:.1f} s",
        g->lo.x, g->lo.y, g->lo.z, g->hi.x, g->hi.y, g->hi.z, g->members.size(), faces.size(),
        r.impostors.size(), r.seconds);
    CellRecord record;
    record.why = r.placement.why;
    record.geometryFaces = r.geometryFaces;
    record.viewLo = g->lo;
    record.viewHi = g->hi;
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
    // The leader's record, then one pointing at it for every other cell.
    CellRecord member;
    member.why =
        fmt::format("part of the view cell of cells ({}, {}, {})-({}, {}, {}), stored with cell {}",
                    g->lo.x, g->lo.y, g->lo.z, g->hi.x, g->hi.y, g->hi.z, g->leader());
    member.viewLo = g->lo;
    member.viewHi = g->hi;
    for (uint32_t c : g->members) {
      std::vector<uint8_t> bytes = encodeCellRecord(c == g->leader() ? record : member);
      journal.append(c, uint32_t(c == g->leader() ? record.impostors.size() : 0), bytes);
      std::lock_guard lock(doneMutex);
      done[c] = std::move(bytes);
    }
    report.computedCells += g->members.size();
    const size_t p = progress += g->members.size();
    if (options.progress) options.progress(p, cells.size());
  }
  std::map<uint32_t, std::vector<uint8_t>> records;
  for (const ViewCellGroup& g : groups) {
    const CellRecord record = decodeCellRecord(done.at(g.leader()), ph.sceneFaces);
    if (!record.impostors.empty()) {
      ++report.viewCellsWithImpostors;
      report.cellsWithImpostors += g.members.size();
    }
    report.impostors += record.impostors.size();
    report.geometryFaces += record.geometryFaces.size();
    for (const StoredImpostor& s : record.impostors) {
      report.points += s.points;
      report.bytes += s.bytes.size();
      report.geometryBytes += s.geometryBytes;
    }
    for (uint32_t c : g.members) records[c] = std::move(done.at(c));
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
