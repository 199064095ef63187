// Errors from untrusted input: the second of vistream's two error channels.
//
// Loaders, parsers and command-line front ends throw InputError when a file,
// a network frame or an argument is wrong. The message names what is wrong
// and where (file and line, element index or frame number). Tools catch it at
// the boundary (main), print it and exit with a non-zero status; servers end
// only the offending session. Nothing that throws InputError may leave a torn
// file or half-updated shared state behind.
#pragma once

#include <fmt/format.h>

#include <stdexcept>
#include <string>

namespace vistream {

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

// Throws InputError with a fmt-formatted message.
template <typename... Args>
[[noreturn]] void throwInputError(fmt::format_string<Args...> format, Args&&... args) {
  throw InputError(fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace vistream
