// The ImpostorData message (protocol/schema/vistream.fbs): one impostor of
// a view cell, or a cell's "none, because ..." as it travels, and the
// checks a receiver applies before using it.
//
// A receiver keeps the impostors of at most kImpostorCellsHeld cells; the
// server mirrors that rule (it sends a cell again once the client dropped
// it), so both sides agree on what the client holds without a reply.
//
// Thread safety: free functions.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "protocol/wire/framing.h"

namespace vistream::wire {

inline constexpr size_t kImpostorCellsHeld = 4;
// A cell has at most this many impostors (the bake's sectors x bands are far fewer).
inline constexpr uint32_t kMaxImpostorsPerCell = 1024;

struct ImpostorMessage {
  // The view cell: grid cells cell..last() (inclusive; cells merged along a
  // street). `cell` names it: the client keeps a view cell's impostors by it.
  glm::ivec3 cell{0};
  std::optional<glm::ivec3> cellHi;  // absent: the cell alone
  glm::ivec3 last() const { return cellHi.value_or(cell); }
  uint32_t index = 0, count = 0;  // count 0: the cell has no impostor (data empty)
  std::string why;
  uint32_t sector = 0, band = 0;
  std::vector<uint32_t> replacedFaces;  // ascending
  std::vector<uint8_t> data;            // protocol/impostor/impostor_codec.h
};

// One frame holding the message.
std::vector<uint8_t> encodeImpostorMessage(const ImpostorMessage& message);

// Reads a verified ImpostorData; false with `error` naming the field when a
// value is out of range: cellHi below cell on an axis, index not below count (or a count of 0 with
// data or an index), a count above kMaxImpostorsPerCell, replaced faces cut off, not ascending or
// not below `faceLimit`. The data's own bytes are checked when decoded (decodeImpostor).
bool readImpostorMessage(const ImpostorData& wire, uint32_t faceLimit, ImpostorMessage& out,
                         std::string& error);

}  // namespace vistream::wire
