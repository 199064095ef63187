// Errors from untrusted input: the second of vistream's two error channels.
//
// Loaders, parsers, command-line front ends and protocol peers throw
// InputError when a file, a network frame or an argument is wrong. The
// message names what is wrong and where (file and line, element index, frame
// or message field); the code says what kind of wrong it is, so a boundary
// can react without reading the text (a server maps it to the wire's
// ErrorCode with wire::wireErrorCode, protocol/wire/messages.h, and nowhere
// else). Tools catch it at the boundary (run*Tool), print it and exit with a
// non-zero status; servers end only the offending session. Nothing that
// throws InputError may leave a torn file or half-updated shared state
// behind. The rule for which channel to use is in CONTRIBUTING.md ("Errors").
#pragma once

#include <fmt/format.h>

#include <cstddef>
#include <cstdint>
#include <iterator>
#include <stdexcept>
#include <string>

namespace vistream {

// What kind of bad input an InputError reports.
enum class InputErrorCode : uint8_t {
  Invalid,        // content that is malformed or out of range (the default)
  BadArgument,    // a command-line option or argument
  BadFile,        // a file that cannot be found, opened or read
  TooLarge,       // over a size limit: triangles in a scene, bytes in a frame
  Unsupported,    // a format, version or feature vistream does not handle
  BadFrame,       // network bytes that are not a valid frame or message
  LimitExceeded,  // a peer went over a rate or count limit
  Unreachable,    // a server that cannot be resolved or reached, or that refused
};

// The code's name ("BadFrame", ...), for logs and JSON.
constexpr const char* inputErrorCodeName(InputErrorCode code) {
  constexpr const char* kNames[] = {"Invalid",     "BadArgument", "BadFile",       "TooLarge",
                                    "Unsupported", "BadFrame",    "LimitExceeded", "Unreachable"};
  return size_t(code) < std::size(kNames) ? kNames[size_t(code)] : "unknown";
}

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what, InputErrorCode code = InputErrorCode::Invalid)
      : std::runtime_error(what), code_(code) {}
  InputError(InputErrorCode code, const std::string& what)
      : std::runtime_error(what), code_(code) {}
  InputErrorCode code() const { return code_; }

 private:
  InputErrorCode code_;
};

// Throws InputError (code Invalid) with a fmt-formatted message.
template <typename... Args>
[[noreturn]] void throwInputError(fmt::format_string<Args...> format, Args&&... args) {
  throw InputError(fmt::format(format, std::forward<Args>(args)...));
}

// Throws InputError with the given code and a fmt-formatted message.
template <typename... Args>
[[noreturn]] void throwInputError(InputErrorCode code, fmt::format_string<Args...> format,
                                  Args&&... args) {
  throw InputError(code, fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace vistream
