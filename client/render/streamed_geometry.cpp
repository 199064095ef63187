#include "client/render/streamed_geometry.h"

#include "common/core/check.h"

namespace vistream {

GeometryChange StreamedGeometry::apply(const GeometryDelta& delta) {
  GeometryChange change;
  if (delta.replaceAll) {
    std::vector<uint32_t> all;
    for (const auto& [face, slots] : faces_) all.push_back(face);
    GeometryDelta drop;
    drop.removed = std::move(all);
    change.removed = apply(drop).removed;
  }
  for (const uint32_t face : delta.removed) {
    const auto it = faces_.find(face);
    if (it == faces_.end()) continue;
    for (uint32_t t = it->second.first; t < it->second.first + it->second.count; ++t) {
      change.removed.push_back(t);
      alive_[t] = 0;
    }
    dead_ += it->second.count;
    faces_.erase(it);
  }
  const RenderGeometry& a = delta.added;
  VS_CHECK_EQ(a.lighting.size(), a.size());
  change.firstAdded = uint32_t(geometry_.size());
  FlatTriangles& to = geometry_.triangles;
  for (size_t t = 0; t < a.size();) {
    // One face's triangles are consecutive in `added`.
    const uint32_t face = a.triangles.faceIds[t];
    size_t end = t + 1;
    while (end < a.size() && a.triangles.faceIds[end] == face) ++end;
    if (const auto held = faces_.find(face); held != faces_.end()) {
      // Sent again without an eviction: the new copy replaces the old.
      const Slots old = held->second;
      VS_CHECK_LT(old.first, change.firstAdded);  // each face once in `added`
      for (uint32_t s = old.first; s < old.first + old.count; ++s) {
        alive_[s] = 0;
        change.removed.push_back(s);
      }
      dead_ += old.count;
    }
    faces_[face] = Slots{uint32_t(to.size()), uint32_t(end - t)};
    for (; t < end; ++t) {
      for (int k = 0; k < 3; ++k) {
        to.positions.push_back(a.triangles.vertex(t, k));
        geometry_.bounds.extend(a.triangles.vertex(t, k));
      }
      to.faceIds.push_back(face);
      to.objectIds.push_back(a.triangles.objectIds[t]);
      to.degenerate.push_back(a.triangles.degenerate[t]);
      geometry_.lighting.appendFrom(a.lighting, t);
      alive_.push_back(1);
    }
  }
  geometry_.sky = a.sky;
  geometry_.haze = a.haze;
  geometry_.groundY = a.groundY;
  geometry_.ground = a.ground;
  return change;
}

RenderGeometry StreamedGeometry::compacted() const {
  RenderGeometry g;
  g.sky = geometry_.sky;
  g.haze = geometry_.haze;
  g.groundY = geometry_.groundY;
  g.ground = geometry_.ground;
  for (size_t t = 0; t < geometry_.size(); ++t)
    if (alive_[t]) appendTriangle(g, geometry_.triangles, geometry_.lighting, t);
  return g;
}

void StreamedGeometry::compact() {
  geometry_ = compacted();
  alive_.assign(geometry_.size(), 1);
  dead_ = 0;
  faces_.clear();
  for (uint32_t t = 0; t < geometry_.size();) {
    const uint32_t face = geometry_.triangles.faceIds[t];
    uint32_t end = t + 1;
    while (end < geometry_.size() && geometry_.triangles.faceIds[end] == face) ++end;
    faces_[face] = Slots{t, end - t};
    t = end;
  }
}

}  // namespace vistream
