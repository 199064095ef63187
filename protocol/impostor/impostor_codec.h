// Impostors as bytes (the impostor database and the wire carry the same
// bytes): a compact, versioned encoding of common/impostor/impostor.h.
//
// Layout (version 1), all integers little-endian:
//   "VIMP", version (1 byte), flags (1 byte: bit 0 = the body is one zstd
//   frame), the body.
//   Body: 33 float32 (cell, box: lo then hi; the sampling plane's origin,
//   u axis, v axis, normal; the three cameras), texture width and height
//   (1 byte each, 1..64), the point count (varint), then
//   - positions: each quantized to 16 bits per axis over the box
//     (q = round((p - lo) / extent * 65535)), the points in Morton order of
//     q, sent as varint deltas of their 48-bit Morton codes;
//   - single-colour flags: one bit a point (LSB first), in that order;
//   - colours: per point its first texel (3 bytes), then for a textured
//     point its other texels as byte-wise differences from the first.
//   zstd compresses the body when that makes it smaller.
// Error bound: a decoded point lies within half a quantization step of the
// original per axis: extent / 131070 (1.1 mm on a 150 m box).
// Points come back in Morton order, not the bake's: an impostor is a set.
//
// Decoding is safe on untrusted bytes: sizes are bounded before anything is
// allocated (kMaxImpostorPoints, kMaxImpostorBodyBytes), every read is
// checked, and a bad impostor yields false and an error naming what is
// wrong.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/impostor/impostor.h"

namespace vistream::wire {

inline constexpr uint32_t kMaxImpostorPoints = 1u << 24;
inline constexpr uint64_t kMaxImpostorBodyBytes = uint64_t(1) << 30;

std::vector<uint8_t> encodeImpostor(const Impostor& impostor);
bool decodeImpostor(std::span<const uint8_t> bytes, Impostor& out, std::string& error);

}  // namespace vistream::wire
