// libFuzzer target: the impostor decoder (protocol/impostor) must refuse any
// bytes with an error or decode them to an impostor that keeps its own
// bounds (every point within its grid's slack of its box, every texel
// offset inside the texels),
// never crash, hang or allocate without bound.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string>

#include "protocol/impostor/impostor_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vistream::wire;
  vistream::Impostor out;
  std::string error;
  if (!decodeImpostor(std::span(data, size), out, error)) {
    if (error.empty()) std::abort();  // a refusal always says why
    return 0;
  }
  if (out.firstTexel.size() != out.size() || out.singleColour.size() != out.size()) std::abort();
  const auto grid = out.pointGrid();
  if (!grid) std::abort();  // a decoded impostor has a grid
  const float slack = grid->slack * 1.001f + 1e-3f;
  const vistream::Box3f grown(out.box.lo - slack, out.box.hi + slack);
  for (size_t k = 0; k < out.size(); ++k) {
    if (!grown.contains(out.points[k])) std::abort();
    const size_t texels = out.singleColour[k] ? 1 : out.textureTexels();
    if (out.firstTexel[k] + texels > out.texels.size()) std::abort();
  }
  // What decodes encodes again and decodes to the same size.
  vistream::Impostor again;
  if (!decodeImpostor(encodeImpostor(out), again, error) || again.size() != out.size())
    std::abort();
  return 0;
}
