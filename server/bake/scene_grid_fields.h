// The scene and grid fields every baked database's FlatBuffer root carries
// (scene_name, scene_fingerprint, scene_faces, origin, grid_lo, cell_size,
// dims: see pvs_database.fbs and impostor_database.fbs), read and checked
// once for all of them.
#pragma once

#include <string>

#include "common/core/error.h"
#include "server/visibility/pvs_database.h"

namespace vistream {

// Fills `h`'s scene and grid from a verified root; throws InputError naming
// the file `name` for a missing vector or an invalid grid. `h.method` is left
// to the caller (its field differs by database).
template <class Root>
void readSceneGridFields(const Root* root, const std::string& name, PvsDatabaseHeader& h) {
  auto vec3 = [&](const auto* v, const char* what) {
    if (!v || v->size() != 3) throwInputError("{}: field '{}' must hold 3 values", name, what);
    return v;
  };
  h.sceneName = root->scene_name() ? root->scene_name()->str() : "";
  h.sceneFingerprint = root->scene_fingerprint();
  h.sceneFaces = root->scene_faces();
  const auto* o = vec3(root->origin(), "origin");
  h.origin = {o->Get(0), o->Get(1), o->Get(2)};
  const auto* lo = vec3(root->grid_lo(), "grid_lo");
  h.gridLo = {lo->Get(0), lo->Get(1), lo->Get(2)};
  const auto* cs = vec3(root->cell_size(), "cell_size");
  h.cellSize = {cs->Get(0), cs->Get(1), cs->Get(2)};
  const auto* d = vec3(root->dims(), "dims");
  h.dims = {d->Get(0), d->Get(1), d->Get(2)};
  for (int a = 0; a < 3; ++a)
    if (!(h.cellSize[a] > 0.0f) || h.dims[a] <= 0 || h.dims[a] > (1 << 20))
      throwInputError("{}: invalid grid (cell size and dims must be positive)", name);
}

}  // namespace vistream
