// Walking a client renderer along a path: cameras from path files, image
// comparison against the reference, and the JSON/table summaries that
// `vistream-client --headless` and `vistream-client-bench` print.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "client/avatar/avatar_view.h"
#include "client/farfield/pipeline.h"
#include "client/render/camera.h"
#include "client/render/image.h"
#include "common/generate/path.h"
#include "common/scene/scene.h"

namespace vistream {

// One camera per path sample, positions converted from file coordinates
// with `origin` (the scene's local origin).
std::vector<Camera> camerasFromPath(const std::vector<PathSample>& path, const glm::dvec3& origin,
                                    int width, int height, float vfovDeg);

// Parses "WxH" (e.g. 640x480); throws InputError naming `option`.
glm::ivec2 parseImageSize(const std::string& text, const char* option = "--size");

struct ImageDifference {
  double differingFraction = 0.0;  // pixels whose colour differs in any channel
  double meanColourError = 0.0;    // mean absolute channel difference over all pixels, in [0, 1]
  // Differing pixels inside a uniform 3x3 patch of the reference: holes and
  // wrong surfaces, as opposed to pixels on edges, where a rasterizer and
  // exact rays (or two rasterizers) may legitimately disagree.
  size_t interiorDiffering = 0;
};
// Both images must have the same size (a broken invariant otherwise: VS_CHECK).
// A pixel differs when a channel differs by more than `tolerance` levels: 0
// between two CPU renderers; 1 against OpenGL, whose interpolation of a
// triangle's colour grid rounds its last float bit differently now and then.
ImageDifference compareImages(const ImageRgb8& image, const ImageRgb8& reference,
                              int tolerance = 0);

struct FrameRecord {
  size_t frame = 0;
  double t = 0.0;
  FrameReport report;
  // Taking up the geometry that arrived before this frame (connected
  // clients: adding and evicting faces in the scene, grids and cache), ms.
  double geometryIntakeMs = 0.0;
  // Wall-clock ms of the frame: geometry intake plus rendering (not the wait
  // for the server, nor the comparison against the reference or writing PNGs).
  double wallMs = 0.0;
  bool compared = false;
  ImageDifference difference;
  std::optional<ImageContrast> contrast;  // of the frame drawn, when measured
  std::optional<AvatarFrame> avatars;     // when the walk shows other users
  size_t avatarPixels = 0;                // pixels the avatars were drawn in (headless)
};

// The headless JSON contract: frames, mean_frame_ms, pixels (means of
// polygon, horizon, cache, ray_hit, ray_miss), per_frame records, plus
// extensions (mode, size, stage summaries, error against the reference,
// geometry_intake_ms_total, geometry_intake_ms_per_frame, wall_ms_per_frame;
// per frame geometry_intake_ms and wall_ms; with avatars, per frame
// `avatars` {in_view, beyond_d, outside_view, poses_shaded, poses_reused,
// vertices_shaded, ms, pixels, why} and stages.avatars as for the pipeline's stages).
nlohmann::json walkthroughJson(const std::vector<FrameRecord>& frames,
                               const PipelineOptions& options, int width, int height);
// The same for people: an aligned table of pixel classes and stage times.
std::string walkthroughTable(const std::vector<FrameRecord>& frames,
                             const PipelineOptions& options);

}  // namespace vistream
