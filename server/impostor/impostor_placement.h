// Where a view cell's impostors go, and how each is framed for sampling
// (Wimmer 2001, sections 5.4.1 and 5.5).
//
// Placement rule (placeImpostors). The thesis forms view cells from street
// segments and places impostors at their ends, and leaves placement open
// ("subject to ongoing research"). Here a view cell is a straight run of the
// bake grid's cells along a street (view_cell_groups.h; the database bake
// merges up to ImpostorBakeOptions::mergeCells), its PVS the union of theirs,
// and its far field is the part of that PVS that lies wholly beyond d (the
// client's near-field distance) from the whole run: triangles that reach
// closer are near field, drawn as polygons. The far field is split by
// azimuth around the cell's centre into `sectors` equal sectors (by the
// triangle's centroid) and each sector into distance bands [d, 2d), [2d, 4d),
// ... (the last band open); each group with at least `minTriangles`
// triangles becomes one impostor, its box the group's bounds. Why sectors:
// an impostor's sampling plane faces one direction, and the thesis's
// resolution heuristic pays for the angle between its cameras as seen from
// the far field (circumradius R against depth z); a sector of 45 degrees keeps
// the shaft narrow, and every point of a sector beyond d lies at least
// d cos(22.5 deg) ahead of the cell along the sector's bisector, so the box
// never reaches the cell for d above a few cell sizes. Why bands: the same
// heuristic sizes the LDI for the nearest depth, so a box reaching from d to
// 8d would sample its far part far too densely. Why a threshold: simulate
// only what the scene calls for; a light far field is cheaper as triangles
// (or ray casting) than as points with textures. Bytes are weighed after the
// bake (maxBytesRatio, 1 by default): an impostor that would cost more bytes
// than the Geometry message of the faces it replaces is not made, and the
// site stays geometry. On cities of plain boxes the codec spends a few bytes
// a triangle, and the nearest band's impostors cost several times their
// geometry (their points are densest per triangle replaced). A site left as
// geometry is still part of the far field the cell needs, so its faces are
// recorded (CellImpostors::geometryFaces) and the server streams them to a
// client that asks for impostors whatever its near-field radius: the thin
// client's far field is whole either way, in whichever form costs less.
//
// Framing (frameImpostor), as in the thesis: the sampling plane has its
// normal from the cell's centre towards the box's centre and lies at the
// cell's far side (the cell wholly behind it); the box must lie wholly
// beyond it, else the impostor is refused (InputError: a cell touching or
// reaching past its impostor's box has no shaft). The shaft is the convex
// hull of cell and box; its section with the plane is the hull of the points
// where segments from cell corners to box corners cross it. The rectangle of
// texture coordinates bounds the section (every ray from the cell to the box
// crosses the plane inside it); the three LDI cameras stand at the corners of
// the triangle of minimum circumference round the section with its top edge
// horizontal (found by a search over the two side slopes).
//
// LDI resolution (ldiPixelAngle), the thesis's heuristic: the screen's pixel
// angle at its centre, divided by the perspective factor (a feature at the
// border of the viewer's field of view projects larger: 1 / cos^2 of half
// the vertical field of view, 1.17 for the thesis's 45 degrees) and by sqrt 2
// (the pixel's diagonal), times z^2 / (R^2 + z^2), the worst mutual
// resolution of three cameras on a circle of radius R seen from depth z (the
// circumcentre of the camera triangle, at the box's nearest depth).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/core/box.h"
#include "common/impostor/impostor.h"
#include "common/scene/scene.h"

namespace vistream {

struct ImpostorFrame {
  SamplingPlane plane;                 // the rectangle of texture coordinates
  std::array<glm::vec3, 3> cameras{};  // corners of the bounding triangle, on the plane
  std::vector<glm::vec2> section;      // the shaft's section, metres along (u, v) from `centre`
  glm::vec3 centre{0.0f};              // the cell's centre moved onto the plane
  float nearestDepth = 0.0f;           // of the box's corners, beyond the plane (metres)
  float circumradius = 0.0f;           // of the camera triangle (metres)
  float trianglePerimeter = 0.0f;
};

// Throws InputError when the box does not lie wholly beyond the cell's far
// side (touching, overlapping or surrounding the cell) or either box is empty.
ImpostorFrame frameImpostor(const Box3f& cell, const Box3f& box);

// What a viewer's screen asks of the samples.
struct ScreenSpec {
  int width = 640, height = 480;  // the thesis's Table 5.1 screen
  float vfovDeg = 60.0f;          // the client's camera

  // The pixel angle at the centre of the screen (radians).
  float pixelAngle() const;
  // The pixel angle that samples must keep below, anywhere on the screen and
  // along any pixel direction: pixelAngle() / (perspective factor * sqrt 2).
  float sampleAngle() const;
};

// The LDI cameras' pixel size (tangent of the angle, at the centre of their
// image planes) for an impostor framed as `frame`, before any resolution factor.
float ldiPixelAngle(const ImpostorFrame& frame, const ScreenSpec& screen);

struct ImpostorPlacementOptions {
  float nearDistance = 150.0f;  // d: the client's near field (PipelineOptions::nearDistance)
  uint32_t sectors = 8;
  uint32_t bands = 3;           // [d, 2d), [2d, 4d), [4d, inf)
  size_t minTriangles = 2'000;  // a lighter group stays geometry
  // After the bake: an impostor whose encoded bytes exceed this many times
  // the Geometry bytes of the faces it replaces stays geometry (0: no limit,
  // the thesis's placement, which Table 5.1's benchmark uses).
  float maxBytesRatio = 1.0f;
};

struct ImpostorSite {
  Box3f box;
  std::vector<uint32_t> triangles;  // indices into the FlatTriangles given
  uint32_t sector = 0, band = 0;
};

struct ImpostorPlacement {
  std::vector<ImpostorSite> sites;
  size_t farTriangles = 0;   // of the PVS, wholly beyond d
  size_t nearTriangles = 0;  // of the PVS, reaching within d (drawn as polygons)
  size_t lightGroups = 0;    // groups below minTriangles, left as geometry
  std::string why;           // one line: what got impostors and why
};

// The impostors of a view cell whose PVS holds `pvsTriangles` (indices into
// `triangles`, the scene's static triangles).
ImpostorPlacement placeImpostors(const Box3f& cell, const FlatTriangles& triangles,
                                 const std::vector<uint32_t>& pvsTriangles,
                                 const ImpostorPlacementOptions& options);

}  // namespace vistream
