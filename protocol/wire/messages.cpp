#include "protocol/wire/messages.h"

namespace vistream::wire {

std::vector<uint8_t> encodeCellReady(const std::vector<glm::ivec3>& cells) {
  CellReadyT ready;
  ready.cells.reserve(cells.size());
  for (const glm::ivec3& c : cells) ready.cells.push_back(toWire(c));
  return encodeMessage(std::move(ready));
}

std::vector<glm::ivec3> readyCells(const CellReady& ready) {
  std::vector<glm::ivec3> out;
  if (const auto* cells = ready.cells()) {
    out.reserve(cells->size());
    for (const CellIndex* c : *cells) out.push_back(fromWire(*c));
  }
  return out;
}

const char* payloadName(Payload p) {
  const char* name = EnumNamePayload(p);
  return name && *name ? name : "unknown";
}

ErrorCode wireErrorCode(InputErrorCode code) {
  switch (code) {
    case InputErrorCode::Invalid:
    case InputErrorCode::BadArgument:
      return ErrorCode::BadRequest;
    case InputErrorCode::TooLarge:
      return ErrorCode::FrameTooLarge;
    case InputErrorCode::Unsupported:
      return ErrorCode::NotSupported;
    case InputErrorCode::BadFrame:
      return ErrorCode::MalformedFrame;
    case InputErrorCode::LimitExceeded:
      return ErrorCode::RateLimited;
    case InputErrorCode::BadFile:      // a file on the receiver's side: its own fault
    case InputErrorCode::Unreachable:  // a third party the receiver could not reach
      return ErrorCode::Internal;
  }
  return ErrorCode::Internal;
}

}  // namespace vistream::wire
