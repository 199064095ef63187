// Impostors as bytes (the impostor database and the wire carry the same
// bytes): a compact, versioned encoding of common/impostor/impostor.h.
//
// Layout (version 2), all integers little-endian:
//   "VIMP", version (1 byte), flags (1 byte, none defined: 0);
//   33 float32 (cell, box: lo then hi; the sampling plane's origin, u axis,
//   v axis, normal; the three cameras), the position step (float32), the
//   colour step, texture width and height (1 byte each), the point count
//   (varint); then four sections, each its stored length (varint), a mode
//   byte (0 raw, 1 one zstd frame) and its bytes:
//   - positions: grid coordinates (Impostor::gridCoordinates), the points in
//     Morton order of them, as varint deltas of their 63-bit Morton codes;
//   - single-colour flags: one bit a point (LSB first), in that order;
//   - colours, channel by channel as multiples of the colour step: each
//     point's first texel as the byte-wise difference from the previous
//     point's;
//   - textures, channel by channel: each textured point's other texels as
//     byte-wise differences from the texel before them.
//   Planar channels and neighbour differences are what lets zstd find the
//   runs: a facade's points share their colour and its changes.
// An impostor the bake made comes back exactly (Impostor::quantize snapped
// it to the grid and colour step it carries); any other is snapped on the
// way: points within half a grid step per axis, texels within half a colour
// step. A decoded point lies within the grid's slack of the box (one that
// float rounding put a little past it is pulled back; one beyond four slacks
// is refused), so what decodes encodes again and decodes. Points come back
// in Morton order, not the bake's: an impostor is a set. Version 1 (one zstd
// frame, 16 bits per axis, no steps) is no longer read: databases are
// rebuilt by a bake.
//
// Decoding is safe on untrusted bytes: sizes are bounded before anything is
// allocated (kMaxImpostorPoints, kMaxImpostorBodyBytes), every read is
// checked, and a bad impostor yields false and an error naming what is
// wrong.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/impostor/impostor.h"

namespace vistream::wire {

inline constexpr uint32_t kMaxImpostorPoints = 1u << 24;
inline constexpr uint64_t kMaxImpostorBodyBytes = uint64_t(1) << 30;

// The encoding's bytes by part, for benchmarks: the header (up to the point
// count) and each section with its length and mode.
struct ImpostorSections {
  size_t header = 0;
  std::array<size_t, 4> bytes{};  // positions, flags, colours, textures
  size_t total() const { return header + bytes[0] + bytes[1] + bytes[2] + bytes[3]; }
};

std::vector<uint8_t> encodeImpostor(const Impostor& impostor, ImpostorSections* sizes = nullptr);
bool decodeImpostor(std::span<const uint8_t> bytes, Impostor& out, std::string& error);

}  // namespace vistream::wire
