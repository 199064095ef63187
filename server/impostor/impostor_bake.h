// Baking a point-based impostor (Wimmer 2001, sections 5.3 and 5.4): its
// points by three perspective layered depth images, their removal where
// another camera samples better and sufficiently, and each point's texture
// by Monte Carlo integration of the plenoptic image function.
//
// Geometric sampling. Each LDI camera (impostor_placement.h: the corners of
// the triangle round the shaft) looks along the sampling plane's normal
// through a window that holds the impostor's box, with square pixels of
// resolutionFactor-th the heuristic's size (ldiPixelAngle). A pixel's ray
// keeps every hit on the impostor's triangles inside the box (the layers,
// at most maxLayers), each a candidate point. Thin geometry (a pole
// narrower than an LDI pixel) can fall between the rays: where a triangle's
// projection comes within half a pixel diagonal of the centre of an LDI
// pixel whose ray met nothing, the point of its edges nearest that centre
// is added, one a pixel. Together these keep every viewer's pixel centre
// that sees the geometry within about 0.6 pixels of a point: the client's
// splat (a disc of 0.7 pixels, client/render/impostor_splat.h) covers it.
//
// The resolution factor stays 1 (the thesis's heuristic) by default. The
// heuristic keeps every edge of a camera's sampling pattern within a pixel
// in any view, so a pixel centre lies within half a pixel of a point; the
// client's disc reaches 0.7, and the 0.2 between is what the seams between
// cameras, layers and surfaces take. Measured along walks through street
// cells of bigcity and of the real city model (bench_impostor_image, 640x480):
// at 0.9 each walk has 2 uncovered pixels over all its impostors, at 0.7 the
// heaviest impostor alone leaves 2 to 5; a splat widened to match a coarser
// sampling (0.88 pixels at 0.8) costs more error on the silhouettes than the
// points it saves. The points per screen pixel follow the screen's field of
// view through the perspective factor: 1.33 at the client's 60 degrees
// against the thesis's 1.17 at 45, (1.33 / 1.17)^2 = 1.3 times the points.
//
// Point removal (optional). Camera j's sample spacing on a surface at p is
// bounded by s_j = a z_j / |n . w_j| (a its pixel size, z_j the depth of p
// along its axis, w_j the unit direction from it, n the surface normal): the
// side of a pixel's footprint perpendicular to the ray, stretched by the
// surface's slant. A viewer at v sees that spacing foreshortened by the same
// slant from its own side, under the angle s_j |n . w_v| / |p - v|; camera j
// samples p sufficiently when that angle stays within the spacing the LDIs
// were sized for (ScreenSpec::sampleAngle over the resolution factor, so that
// a coarser resolution gives fewer points, not three cameras' worth of points
// nobody samples sufficiently) for every viewer in the cell (taken at the
// cell's corners and centre: the cell is small against p's distance), so no
// viewer sees two neighbouring samples more than a pixel apart (the thesis:
// no edge of the camera's sampling pattern projects to more than a pixel in
// any view). Judging s_j against the distance alone would call every
// surface seen obliquely undersampled and keep all three cameras' points
// there, three times what a street's side walls need. A point from camera k is
// dropped when another camera samples its surface sufficiently and better
// (smaller s, ties to the lower camera) and has a sample of that surface
// within 0.75 s_j of it (half its grid's diagonal, and a margin); the better
// camera's own samples there remain, so no region loses all its points. A
// camera may sample a surface better yet have no sample of it where its
// rays met the surface's occluders or stopped at maxLayers: the point stays
// (ImpostorStats::keptUnsampled counts them). A second pass checks each
// dropped point against the points that stay, since the one it was dropped
// for may itself have gone for a third camera's, and keeps it if none covers
// it any more. Beyond the thesis, thinning (thinOversampled): where the
// camera that kept a point samples its surface at least sqrt(2) times finer
// than sufficient, its samples on the even squares of its LDI's checkerboard
// form a lattice of spacing sqrt(2) s_j, still sufficient, and a point on an
// odd square goes when all four of its edge neighbours in the LDI hold kept
// points of its surface (none is thinned at an edge). Most points sit just
// under the sufficient spacing (the LDI is sized for the worst viewer), so
// this thins a few percent: surfaces a camera sees more squarely than any
// viewer does.
//
// Hidden points (optional, on by default). The LDIs keep every layer, and
// most of those layers (the backs and insides of buildings, rows behind
// rows) are hidden from the whole view cell by the impostor's own surfaces:
// in the thesis's terms their visibility term v_j is 0 for every camera, so
// their weight c_j is undefined and they only cost memory and fill. A point
// is kept when an occlusion ray against the impostor's triangles reaches it
// from at least one of `visibilityViews` viewpoints in the view cell
// (stratified: a jittered grid, then random ones). A point seen from less
// than about 1/visibilityViews of the cell can be lost; the no-holes tests
// bound what that costs.
//
// Appearance (the plenoptic image function). For texel i of point p, c_i is
// the integral of PIF(s, theta, x) against the texel's filter over viewer
// positions s on the sampling rectangle (a Gaussian of half a texel about
// the texel's centre) and the monitor's filter over pixels x (the pixel p
// projects to, after a uniformly random camera orientation, which places p
// anywhere in its pixel: a box; the thesis widens it by a Gaussian of about
// half a pixel, pixelFilterSigma, which blurs every crease and roof line by
// a pixel more than the box-filtered pixels of the renderers and of the
// benchmarks' supersampled reference: on the real city model the error
// inside the impostors' footprint halves without it), counting only
// views where p is visible (an occlusion ray from s to p against the
// impostor's triangles: the points' z-buffer). PIF is what a ray from s
// sees beyond the box's entry: the first scene triangle's baked colour with
// the haze of its distance, or the backdrop. Rays go in until the standard
// error of the texel's mean falls below varianceThreshold (8-bit levels,
// per channel) after minRays, or maxRays were tried. A texel that never saw
// its point takes the mean of the point's other texels, and a point never
// seen from the rectangle the colour of its surface.
//
// Compression: a point whose texels all lie within singleColourTolerance of
// their mean (per channel) keeps one colour. The default, 12 levels, is three
// standard errors at the default variance threshold: texels that differ by
// no more than the Monte Carlo's own noise are one colour.
//
// Determinism: every point's rays are seeded by the point, so a bake gives
// the same bytes on any thread count.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "common/core/stats_fields.h"
#include "common/impostor/impostor.h"
#include "common/light/lighting.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "server/impostor/impostor_placement.h"

namespace vistream {

// The scene as the impostor bake sees it: its static triangles with their
// baked colours and backdrop, and an Embree query over all of them (what the
// plenoptic image function samples).
struct ImpostorScene {
  const FlatTriangles& triangles;
  const RayQuery& rays;
  const LightingGrid& lighting;
  Backdrop backdrop;
  std::optional<float> groundY;  // local height of an assumed ground plane
};

struct ImpostorOptions {
  ScreenSpec screen;
  float resolutionFactor = 1.0f;  // LDI pixels per heuristic pixel, per axis
  bool removePoints = true;
  // With removePoints: thin a camera's samples to its LDI's even squares
  // where it samples a surface sqrt(2) times finer than sufficient.
  bool thinOversampled = true;
  bool cullHidden = true;         // drop points no viewpoint in the cell sees
  uint32_t visibilityViews = 64;  // viewpoints tried per point before it counts as hidden
  uint32_t maxLayers = 8;
  uint32_t textureWidth = 8, textureHeight = 2;
  float varianceThreshold = 4.0f;       // standard error of a texel's mean, 8-bit levels
  float pixelFilterSigma = 0.0f;        // the Gaussian widening the pixel's box, in pixels
  uint32_t minRays = 8, maxRays = 64;   // per texel
  float singleColourTolerance = 12.0f;  // 8-bit levels
  // Precision kept (Impostor::quantize, what the encoding carries): a point
  // moves by at most positionError of the screen's smallest pixel angle
  // seen from anywhere in the cell (PointGrid; 0: 16 bits per axis of the
  // grid's range), and the texels of textured points snap to multiples of
  // colourStep levels (1, 2, 4, 8 or 16; single colours stay exact). The
  // defaults cost nothing measurable: along walks through street cells of
  // bigcity and the real city model, the image error and the holes are
  // those of the unquantized points within the walks' noise (README); 0.05
  // takes a quarter of the 0.2 pixels the splat's 0.7 leaves beyond the
  // sampling's half pixel.
  float positionError = 0.05f;  // pixels
  uint32_t colourStep = 8;
  uint64_t seed = 1;
  // Bounded work: an impostor whose LDIs would need more pixels is refused
  // (InputError naming the figure), before any ray is cast.
  uint64_t maxLdiPixels = 12'000'000;
};

struct ImpostorStats {
  std::array<uint64_t, 3> ldiWidth{}, ldiHeight{};
  float ldiPixelAngle = 0.0f;  // radians (tangent) at the cameras' centres
  uint64_t samples = 0;        // LDI hits in the box (candidate points), thin ones included
  uint64_t thinSamples = 0;    // added for thin geometry between LDI rays
  uint64_t removed = 0;        // dropped by point removal
  // Kept by point removal though another camera samples their surface
  // better and sufficiently: it has no sample beside them (its rays met an
  // occluder there or stopped at maxLayers).
  uint64_t keptUnsampled = 0;
  // Dropped by thinning (of `removed`): their camera's neighbours on the
  // LDI's even squares sample the surface sufficiently.
  uint64_t thinned = 0;
  uint64_t hidden = 0;  // dropped as hidden from the whole cell
  uint64_t points = 0;
  uint64_t singleColour = 0;    // points keeping one colour
  uint64_t appearanceRays = 0;  // PIF rays
  uint64_t visibilityRays = 0;  // occlusion rays from the rectangle to points
  uint64_t unseenPoints = 0;    // never visible from the rectangle
  // For the view from the cell's centre towards the box's centre on the
  // screen: the points' screen bounding box (Table 5.1's "approx. #screen
  // pixels"), and the pixels holding at least one point.
  uint64_t screenPixels = 0, coveredPixels = 0;
  double pointsPerPixel = 0.0;         // points / screenPixels (Table 5.1)
  double pointsPerCoveredPixel = 0.0;  // points / coveredPixels
  uint64_t bytes = 0;  // encoded (protocol/impostor): what the wire and the database hold
  // Of `bytes`: the positions, the colours (single-colour flags and every
  // point's first texel) and the textures' other texels.
  uint64_t positionBytes = 0, colourBytes = 0, textureBytes = 0;
  uint64_t memoryBytes = 0;        // in memory (Impostor::bytes)
  uint64_t bytesUncompressed = 0;  // in memory, every point with its whole texture
  double sampleSeconds = 0.0, removeSeconds = 0.0, hiddenSeconds = 0.0, appearanceSeconds = 0.0,
         seconds = 0.0;

  uint64_t ldiPixels() const {
    return ldiWidth[0] * ldiHeight[0] + ldiWidth[1] * ldiHeight[1] + ldiWidth[2] * ldiHeight[2];
  }
  // Every field once, for JSON and tables (common/core/stats_output.h); the
  // three LDIs' sizes as their total.
  template <class F>
  void forEachField(F&& f) const {
    f(StatField{"ldi_pixels", "LDI pixels (three cameras)", ""}, ldiPixels());
    f(StatField{"ldi_pixel_angle", "LDI pixel angle", "rad"}, ldiPixelAngle);
    f(StatField{"samples", "samples", ""}, samples);
    f(StatField{"thin_samples", "of which for thin geometry", ""}, thinSamples);
    f(StatField{"removed", "removed", ""}, removed);
    f(StatField{"kept_unsampled", "kept: the better camera has no sample there", ""},
      keptUnsampled);
    f(StatField{"thinned", "of those removed, thinned: their camera oversamples", ""}, thinned);
    f(StatField{"hidden", "hidden from the cell", ""}, hidden);
    f(StatField{"points", "points", ""}, points);
    f(StatField{"single_colour", "single-colour points", ""}, singleColour);
    f(StatField{"appearance_rays", "appearance rays", ""}, appearanceRays);
    f(StatField{"visibility_rays", "visibility rays", ""}, visibilityRays);
    f(StatField{"unseen_points", "points unseen from the cell", ""}, unseenPoints);
    f(StatField{"screen_pixels", "screen pixels (bounding box)", ""}, screenPixels);
    f(StatField{"covered_pixels", "screen pixels covered", ""}, coveredPixels);
    f(StatField{"points_per_pixel", "points per screen pixel", ""}, pointsPerPixel);
    f(StatField{"points_per_covered_pixel", "points per covered pixel", ""}, pointsPerCoveredPixel);
    f(StatField{"bytes", "bytes encoded", ""}, bytes);
    f(StatField{"position_bytes", "of which positions", ""}, positionBytes);
    f(StatField{"colour_bytes", "of which colours", ""}, colourBytes);
    f(StatField{"texture_bytes", "of which textures", ""}, textureBytes);
    f(StatField{"memory_bytes", "bytes in memory", ""}, memoryBytes);
    f(StatField{"bytes_uncompressed", "bytes in memory without single colours", ""},
      bytesUncompressed);
    f(StatField{"sample_s", "sampling", "s"}, sampleSeconds);
    f(StatField{"remove_s", "point removal", "s"}, removeSeconds);
    f(StatField{"hidden_s", "hidden points", "s"}, hiddenSeconds);
    f(StatField{"appearance_s", "appearance", "s"}, appearanceSeconds);
    f(StatField{"bake_s", "bake", "s"}, seconds);
  }
};

// Bakes the impostor of `triangles` (indices into scene.triangles, the
// geometry it replaces) inside `box` for `cell`. Throws InputError for a
// box that reaches the cell (frameImpostor) or needs more than maxLdiPixels.
Impostor bakeImpostor(const ImpostorScene& scene, const Box3f& cell, const Box3f& box,
                      const std::vector<uint32_t>& triangles, const ImpostorOptions& options,
                      ImpostorStats* stats = nullptr);
// The same within a byte budget (0: none): nothing when the points' encoded
// positions alone (a part of the encoding that does not depend on their
// colours) exceed maxBytes, found before the appearance is integrated;
// `stats` then holds the sampling's figures, points and positionBytes.
std::optional<Impostor> bakeImpostorWithin(const ImpostorScene& scene, const Box3f& cell,
                                           const Box3f& box, const std::vector<uint32_t>& triangles,
                                           const ImpostorOptions& options, uint64_t maxBytes,
                                           ImpostorStats* stats = nullptr);

// The screen pixels that impostor's points fall on for a viewer at `eye`
// looking at `target` (a planar projection of the screen's pixel angle,
// unbounded, so a wide impostor is counted whole), and their bounding box.
struct ScreenCoverage {
  uint64_t pixels = 0, boxPixels = 0;
};
ScreenCoverage screenCoverage(const std::vector<glm::vec3>& points, const glm::vec3& eye,
                              const glm::vec3& target, const ScreenSpec& screen);

}  // namespace vistream
