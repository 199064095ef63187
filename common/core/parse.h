// Parsing numbers from command-line arguments (untrusted input: errors are
// InputError naming the option and the offending text).
#pragma once

#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include "common/core/error.h"

namespace vistream {

// Parses `count` comma-separated finite numbers, e.g. "0,0,0,1,2,1"; count 0
// takes any number of them (at least one).
inline std::vector<double> parseNumberList(std::string_view text, size_t count,
                                           std::string_view option) {
  std::vector<double> out;
  size_t pos = 0;
  while (pos <= text.size()) {
    const size_t comma = text.find(',', pos);
    std::string_view tok =
        text.substr(pos, comma == std::string_view::npos ? std::string_view::npos : comma - pos);
    while (!tok.empty() && tok.front() == ' ') tok.remove_prefix(1);
    while (!tok.empty() && tok.back() == ' ') tok.remove_suffix(1);
    double v = 0.0;
    const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
    if (tok.empty() || ec != std::errc() || ptr != tok.data() + tok.size() || !std::isfinite(v))
      throwInputError("{}: '{}' is not a finite number (in '{}')", option, tok, text);
    out.push_back(v);
    if (comma == std::string_view::npos) break;
    pos = comma + 1;
  }
  if (count != 0 && out.size() != count)
    throwInputError("{}: expected {} comma-separated numbers, got {} in '{}'", option, count,
                    out.size(), text);
  return out;
}

}  // namespace vistream
