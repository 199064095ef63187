// libFuzzer target: FrameDecoder must reject or accept any byte stream
// without crashing, every frame it returns must be readable, and a Geometry
// frame must decode or be rejected.
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/geometry/geometry_codec.h"
#include "protocol/wire/framing.h"
#include "protocol/wire/messages.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  vistream::wire::FrameDecoder decoder(1u << 16);
  // Feed in two pieces to exercise reassembly.
  const size_t half = size / 2;
  for (auto piece :
       {std::span<const uint8_t>(data, half), std::span<const uint8_t>(data + half, size - half)}) {
    if (!decoder.feed(piece)) break;
    while (auto frame = decoder.next()) {
      const auto* env = vistream::wire::envelopeOf(*frame);
      if (const auto* hello = env->payload_as_Hello())
        if (hello->auth_token()) (void)hello->auth_token()->size();
      if (const auto* err = env->payload_as_Error())
        if (err->text()) (void)err->text()->str();
      if (const auto* g = env->payload_as_Geometry()) {
        vistream::wire::DecodedGeometry out;
        std::string error;
        (void)vistream::wire::decodeGeometry(*g, vistream::wire::QuantizationGrid{}, out, error);
      }
      if (const auto* p = env->payload_as_Pose()) (void)vistream::wire::isFinite(p->position());
      if (const auto* r = env->payload_as_CellReady()) (void)vistream::wire::readyCells(*r);
    }
  }
  return 0;
}
