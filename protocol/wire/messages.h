// Typed messages: encoding any message of the schema into a frame, and the
// checks every receiver applies beyond the FlatBuffers Verifier.
//
// Messages are built with FlatBuffers' object API (HelloT, PoseT, ...,
// generated from protocol/schema/vistream.fbs); encodeMessage() wraps one in
// an Envelope and a frame. Receivers read the verified Envelope in place
// (envelopeOf() in framing.h) and use the helpers below for the values the
// Verifier cannot judge (non-finite numbers, sizes).
#pragma once

#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "protocol/wire/framing.h"

namespace vistream::wire {

// One frame holding `message` (a native table type of the Payload union).
template <class NativeTable>
std::vector<uint8_t> encodeMessage(NativeTable message) {
  EnvelopeT envelope;
  envelope.payload.Set(std::move(message));
  flatbuffers::FlatBufferBuilder b(256);
  b.Finish(Envelope::Pack(b, &envelope));
  return encodeFrame(b);
}

inline Vec3d toWire(const glm::dvec3& v) {
  return Vec3d(v.x, v.y, v.z);
}
inline Vec3f toWire(const glm::vec3& v) {
  return Vec3f(v.x, v.y, v.z);
}
inline CellIndex toWire(const glm::ivec3& c) {
  return CellIndex(c.x, c.y, c.z);
}
inline glm::dvec3 fromWire(const Vec3d& v) {
  return {v.x(), v.y(), v.z()};
}
inline glm::vec3 fromWire(const Vec3f& v) {
  return {v.x(), v.y(), v.z()};
}
inline glm::ivec3 fromWire(const CellIndex& c) {
  return {c.i(), c.j(), c.k()};
}

inline bool isFinite(const Vec3d* v) {
  return v && std::isfinite(v->x()) && std::isfinite(v->y()) && std::isfinite(v->z());
}
inline bool isFinite(const Vec3f* v) {
  return v && std::isfinite(v->x()) && std::isfinite(v->y()) && std::isfinite(v->z());
}

// CellReady (version 3): one frame for every cell that became ready at once.
std::vector<uint8_t> encodeCellReady(const std::vector<glm::ivec3>& cells);
// The cells a verified CellReady announces, in the order sent (none if the
// field is missing). Any cell index may come from the wire: the caller
// checks it against its grid before indexing with it.
std::vector<glm::ivec3> readyCells(const CellReady& ready);

// The payload's name, for logs and errors ("Hello", "Pose", ...).
const char* payloadName(Payload p);

// The one mapping from InputError codes (common/core/error.h) to the wire's
// ErrorCode: a peer that refuses input it received sends this code.
ErrorCode wireErrorCode(InputErrorCode code);

}  // namespace vistream::wire
