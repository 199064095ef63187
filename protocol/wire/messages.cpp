#include "protocol/wire/messages.h"

namespace vistream::wire {

const char* payloadName(Payload p) {
  const char* name = EnumNamePayload(p);
  return name && *name ? name : "unknown";
}

ErrorCode wireErrorCode(InputErrorCode code) {
  switch (code) {
    case InputErrorCode::Invalid:
    case InputErrorCode::BadArgument:
      return ErrorCode::BadRequest;
    case InputErrorCode::TooLarge:
      return ErrorCode::FrameTooLarge;
    case InputErrorCode::Unsupported:
      return ErrorCode::NotSupported;
    case InputErrorCode::BadFrame:
      return ErrorCode::MalformedFrame;
    case InputErrorCode::LimitExceeded:
      return ErrorCode::RateLimited;
    case InputErrorCode::BadFile:      // a file on the receiver's side: its own fault
    case InputErrorCode::Unreachable:  // a third party the receiver could not reach
      return ErrorCode::Internal;
  }
  return ErrorCode::Internal;
}

}  // namespace vistream::wire
