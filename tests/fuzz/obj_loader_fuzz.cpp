// libFuzzer target: the OBJ loader must turn any bytes into a Scene or an
// InputError, never a crash, a hang or unbounded memory.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const vistream::Scene scene = vistream::loadObjFromMemory(text, "fuzz.obj");
    (void)scene.triangleCount();
  } catch (const vistream::InputError&) {
  }
  return 0;
}
