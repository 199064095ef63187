#include "protocol/wire/messages.h"

namespace vistream::wire {

const char* payloadName(Payload p) {
  const char* name = EnumNamePayload(p);
  return name && *name ? name : "unknown";
}

}  // namespace vistream::wire
