// `vistream-pvs impostor-bench`: Table 5.1 of Wimmer 2001 (chapter 5) and
// what the impostors' accuracy knobs cost, on bigcity and the real city
// model.
//
// Per scene: one street view cell, its impostors placed (with a lower
// triangle threshold than the bake's, 300, so the real city's cell has
// three) and baked with the defaults; the three with the most triangles make the table's columns
// (points, points per screen pixel, approximate screen pixels, bake time,
// memory without single colours as the thesis lists it, encoded bytes, and
// the bytes of the far-field geometry it replaces). Then the first of them
// is baked again with one knob changed at a time: the LDI resolution factor,
// point removal, hidden-point culling, the texture size (1x1, 4x2, 8x2,
// 16x4) and the Monte Carlo variance threshold, each row with its points,
// points per pixel, bytes, single-colour share, rays and bake time (the
// median of `repeats` runs).
//
// Image error against a supersampled reference and frame rates need the
// client's renderers: vistream-client-bench measures those (the server never
// links the client).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "server/impostor/impostor_placement.h"

namespace vistream {

struct ImpostorBenchOptions {
  std::vector<std::string> scenes;  // default: bigcity and ../shared/data/delfshaven.obj
  std::string cell;                 // x0,y0,z0,x1,y1,z1 (file coordinates) for every scene
  ImpostorPlacementOptions placement;
  ScreenSpec screen;                    // the viewer's screen (Table 5.1: 640x480)
  std::filesystem::path lightingCache;  // empty: bake the lighting every time
  size_t repeats = 3;                   // bake times are medians over this many runs
  bool sweep = true;
  bool json = false;
};

ImpostorBenchOptions defaultImpostorBenchOptions();
int runImpostorBench(const ImpostorBenchOptions& options);

}  // namespace vistream
