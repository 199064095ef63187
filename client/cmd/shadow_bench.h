// `vistream-client-bench --shadows`: what self-shadowing's accuracy costs in
// time (Kautz, Lehtinen and Aila 2004, Tables 1 and 2), on any skinned glTF
// model animated by its first clip.
//
// For each frame of the clip (evenly spaced), the model is posed (linear
// blend skinning and normals: "transform") and every vertex's transfer
// vector computed (rasterization and integration); frame times are medians
// over the frames. The reference is Monte Carlo transfer with 65,536 Embree
// rays a vertex (two independent halves, whose difference estimates its own
// error: JSON `reference_error`) on a subset of the frames, for every vertex
// up to 2,000 vertices and for an even sample of 1,000 above; the error is
// the mean relative L2 distance of the transfer vectors to it over those
// vertices. Monte Carlo itself is
// swept (64 to 16,384 rays a vertex, every vertex; another seed)
// and its time at our error interpolated on a log-log line (error falling
// as rays^-1/2 beyond the sweep). The per-vertex PVS (section 3.2) is built
// from poses between the benchmark's frames and run as Table 1's "with PVS"
// columns (JSON `with_pvs`). Each knob (mask side, plane table, SH terms,
// downsampling, mesh hierarchy ring) is then varied alone around the defaults.
#pragma once

#include <string>

namespace vistream {

struct ShadowBenchArgs {
  std::string model;
  int subdivide = 0;
  int subdivideBy = 4;  // 4: at edge midpoints; 3: around centroids
  int frames = 8;
  int referenceFrames = 2;
  bool quick = false;  // fewer knob values and Monte Carlo rays (tests)
  // A PNG of the first reference frame: the model unshadowed, shadowed by
  // this method and by the Monte Carlo reference, side by side.
  std::string png;
  // An equirectangular HDR environment to light the PNG with; empty: the
  // model's scene environment (the analytic sky for a bare glTF).
  std::string environment;
  bool json = false;
  // The glossy rows (JSON `glossy`): a normalized Phong lobe of this
  // exponent about each front-facing vertex's reflection of a viewer at the
  // figure's camera, from the same masks (per pixel, and in 4 x 4 blocks),
  // against a Monte Carlo reference and sweep of its own; the error is the
  // relative L2 distance of all the facing vertices' coefficients together
  // (a per-vertex mean is dominated by lobes almost wholly blocked). 0: none.
  float glossExponent = 16.0f;
};

// Returns 0 on success; throws InputError for a model it cannot use.
int runShadowBench(const ShadowBenchArgs& args);

}  // namespace vistream
