// Parsing numbers from command-line arguments (untrusted input: errors are
// InputError naming the option and the offending text).
#pragma once

#include <algorithm>
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

// Parses "WIDTHxHEIGHT" (two whole numbers, e.g. "640x480"), each side in
// [lo, hi]; `option` names the argument in errors.
struct WidthHeight {
  int width = 0, height = 0;
};
inline WidthHeight parseWidthHeight(std::string_view text, std::string_view option, int lo,
                                    int hi) {
  const size_t x = text.find('x');
  WidthHeight out;
  auto whole = [](std::string_view part, int& v) {
    const auto [ptr, ec] = std::from_chars(part.data(), part.data() + part.size(), v);
    return !part.empty() && ec == std::errc() && ptr == part.data() + part.size();
  };
  if (x == std::string_view::npos || !whole(text.substr(0, x), out.width) ||
      !whole(text.substr(x + 1), out.height))
    throwInputError("{} {}: expected WIDTHxHEIGHT, e.g. {}x{}", option, text, std::max(lo, 8),
                    std::max(lo, 4));
  if (out.width < lo || out.height < lo || out.width > hi || out.height > hi)
    throwInputError("{} {}: each side must lie in [{}, {}]", option, text, lo, hi);
  return out;
}

}  // namespace vistream
