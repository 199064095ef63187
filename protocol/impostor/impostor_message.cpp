#include "protocol/impostor/impostor_message.h"

#include <fmt/format.h>

#include "protocol/geometry/byte_coding.h"
#include "protocol/wire/messages.h"

namespace vistream::wire {

std::vector<uint8_t> encodeImpostorMessage(const ImpostorMessage& m) {
  ImpostorDataT t;
  t.cell = std::make_unique<CellIndex>(toWire(m.cell));
  if (m.last() != m.cell) t.cell_hi = std::make_unique<CellIndex>(toWire(m.last()));
  t.index = uint16_t(m.index);
  t.count = uint16_t(m.count);
  t.why = m.why;
  t.sector = uint8_t(m.sector);
  t.band = uint8_t(m.band);
  putVarint(t.replaced_faces, m.replacedFaces.size());
  putAscending(t.replaced_faces, m.replacedFaces);
  t.data = m.data;
  return encodeMessage(std::move(t));
}

bool readImpostorMessage(const ImpostorData& wire, uint32_t faceLimit, ImpostorMessage& out,
                         std::string& error) {
  auto fail = [&](std::string text) {
    error = "ImpostorData: " + std::move(text);
    return false;
  };
  if (!wire.cell()) return fail("no cell");
  out.cell = fromWire(*wire.cell());
  out.cellHi.reset();
  if (wire.cell_hi()) out.cellHi = fromWire(*wire.cell_hi());
  if (glm::any(glm::lessThan(out.last(), out.cell)))
    return fail(fmt::format("cell_hi ({}, {}, {}) lies below cell ({}, {}, {})", out.last().x,
                            out.last().y, out.last().z, out.cell.x, out.cell.y, out.cell.z));
  out.index = wire.index();
  out.count = wire.count();
  if (out.count > kMaxImpostorsPerCell)
    return fail(fmt::format("count {} exceeds {}", out.count, kMaxImpostorsPerCell));
  const bool hasData = wire.data() && wire.data()->size() > 0;
  if (out.count == 0 && (out.index != 0 || hasData))
    return fail("a cell without impostors carries an index or data");
  if (out.count > 0 && out.index >= out.count)
    return fail(fmt::format("index {} is not below count {}", out.index, out.count));
  if (out.count > 0 && !hasData) return fail("an impostor without data");
  out.why = wire.why() ? wire.why()->str() : std::string();
  out.sector = wire.sector();
  out.band = wire.band();
  out.replacedFaces.clear();
  if (const auto* bytes = wire.replaced_faces(); bytes && bytes->size() > 0) {
    PayloadReader r(std::span<const uint8_t>(bytes->data(), bytes->size()));
    // Every face costs at least a byte: a count beyond the bytes left is a lie.
    const auto n =
        r.varint("the replaced face count", std::min<uint64_t>(faceLimit, r.remaining()));
    if (!n || !readAscending(r, size_t(*n), faceLimit, "a replaced face ID", out.replacedFaces))
      return fail(r.error());
    if (r.remaining() > 0)
      return fail(fmt::format("{} bytes after the replaced faces", r.remaining()));
  }
  out.data.clear();
  if (hasData) out.data.assign(wire.data()->begin(), wire.data()->end());
  return true;
}

}  // namespace vistream::wire
