// libFuzzer target: FrameDecoder must reject or accept any byte stream
// without crashing, every frame it returns must be readable, and a Geometry
// or ImpostorData frame must decode or be rejected (an accepted impostor
// message keeps the bounds readImpostorMessage promises).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "protocol/geometry/geometry_codec.h"
#include "protocol/impostor/impostor_codec.h"
#include "protocol/impostor/impostor_message.h"
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
      if (const auto* i = env->payload_as_ImpostorData()) {
        constexpr uint32_t kFaces = 1u << 20;
        vistream::wire::ImpostorMessage m;
        std::string error;
        if (!vistream::wire::readImpostorMessage(*i, kFaces, m, error)) {
          if (error.empty()) std::abort();  // a refusal always says why
          continue;
        }
        if (m.count > vistream::wire::kMaxImpostorsPerCell) std::abort();
        if (glm::any(glm::lessThan(m.last(), m.cell))) std::abort();
        if (m.count == 0 ? (!m.data.empty() || m.index != 0) : m.index >= m.count) std::abort();
        for (size_t k = 0; k < m.replacedFaces.size(); ++k)
          if (m.replacedFaces[k] >= kFaces ||
              (k > 0 && m.replacedFaces[k] < m.replacedFaces[k - 1]))
            std::abort();
        vistream::Impostor imp;
        (void)vistream::wire::decodeImpostor(m.data, imp, error);
      }
    }
  }
  return 0;
}
