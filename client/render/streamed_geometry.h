// The geometry a connected client holds, changed in place as faces arrive
// and leave, so the renderers can take up each change instead of rebuilding.
//
// Triangles live in slots of one RenderGeometry: a face that arrives is
// appended (its triangles take the next slots); a face evicted (or sent again,
// which replaces it) leaves its slots behind, still holding its corners, and
// the GeometryChange returned by apply() names them so the renderers drop
// them (FrameRenderer::update). Slot indices never move until compacted(),
// which the owner calls when dead slots outnumber live ones, and then builds
// its renderers again.
//
// Thread safety: none; one owner, one thread.
#pragma once

#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "client/render/render_geometry.h"

namespace vistream {

// What changed in a client's geometry since the last delta (a StreamClient's
// takeDelta()): faces to drop, and faces to add.
struct GeometryDelta {
  // Drop every face held before taking up this delta (which then carries
  // everything the source holds).
  bool replaceAll = false;
  // Face IDs to drop: evicted, or about to be replaced by a new version in
  // `added`. IDs not held are ignored.
  std::vector<uint32_t> removed;
  // The triangles of the faces to add, with face IDs and colours, each
  // face's triangles consecutive and each face once (VS_CHECK). Its sky and
  // groundY are the current ones.
  RenderGeometry added;
  uint64_t version = 0;  // the source's version this delta brings the holder to
};

// The slots a change touched, for FrameRenderer::update.
struct GeometryChange {
  uint32_t firstAdded = 0;        // slots [firstAdded, size()) are new
  std::vector<uint32_t> removed;  // slots whose triangles left (dead from now on)

  bool empty(size_t size) const { return removed.empty() && firstAdded == size; }
};

class StreamedGeometry {
 public:
  // Applies a delta: removes, then appends. Returns the slots touched.
  GeometryChange apply(const GeometryDelta& delta);

  const RenderGeometry& geometry() const { return geometry_; }
  size_t faces() const { return faces_.size(); }
  size_t liveTriangles() const { return geometry_.size() - dead_; }
  size_t deadTriangles() const { return dead_; }
  // Whether slot t holds a triangle of a face still held.
  bool live(uint32_t t) const { return t < alive_.size() && alive_[t] != 0; }

  // The live triangles only, in slot order (what a renderer built from
  // scratch would be given); replaces the slots with them when `compact`.
  RenderGeometry compacted() const;
  void compact();

 private:
  struct Slots {
    uint32_t first = 0, count = 0;
  };
  RenderGeometry geometry_;
  std::vector<uint8_t> alive_;  // per slot
  std::unordered_map<uint32_t, Slots> faces_;
  size_t dead_ = 0;
};

}  // namespace vistream
