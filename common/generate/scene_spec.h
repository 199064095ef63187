// Naming a scene on a command line: a file path (.obj, .gltf, .glb, .json
// manifest) or the name of a built-in procedural scene (city1, city2,
// bigcity, interior, terrain), optionally with a seed: "city1@7".
// A path that exists always wins over a built-in name.
#pragma once

#include <string>

#include "common/scene/scene.h"

namespace vistream {

// Throws InputError if the spec is neither an existing file nor a built-in name.
Scene openScene(const std::string& spec);

}  // namespace vistream
