// The shape every vistream command-line tool shares: one CLI11 app with
// subcommands, a --log-level that may come before or after the subcommand,
// help that shows every option's default, and one boundary where errors
// become exit codes:
//   0  success;
//   1  bad input, with "tool: error: ..." on stderr: a file that cannot be
//      read, and an option value out of its range or not a number (the
//      range validators below run at parse time, before any scene loads,
//      and the message names the option);
//   2  bad usage: an unknown option or subcommand, a required one missing.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "common/core/error.h"
#include "common/core/log.h"
#include "common/light/lighting_cache.h"
#include "common/scene/scene_loader.h"
#include "common/world/static_world.h"

namespace vistream {

// Range validators for numeric options. CLI11 runs them on the text given,
// before converting it, so "-1" never wraps around to 2^64-1 in a size_t.
// The text must be a finite number (an integer for integral T) inside the
// range; otherwise parsing fails with a ValidationError whose message names
// the option: "--port: must be an integer in 1..65535, got '99999'".
namespace cli_detail {

template <typename T>
CLI::Validator numberCheck(long double lo, long double hi, std::string rule,
                           bool exclusive = false) {
  constexpr bool kIntegral = std::is_integral_v<T>;
  return CLI::Validator(
      [lo, hi, rule, exclusive](std::string& input) -> std::string {
        const char* begin = input.c_str();
        char* end = nullptr;
        const long double v = std::strtold(begin, &end);
        const bool parsed = end != begin && *end == '\0' && std::isfinite(v);
        const bool inside = exclusive ? (v > lo && v < hi) : (v >= lo && v <= hi);
        if (!parsed || (kIntegral && v != std::floor(v)) || !inside)
          return "must be " + rule + ", got '" + input + "'";
        return std::string();
      },
      rule);
}

template <typename T>
std::string numberText(T v) {
  std::string s = std::to_string(v);
  if constexpr (!std::is_integral_v<T>) {
    // Trailing zeros off: 0.500000 -> 0.5, 180.000000 -> 180.
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.pop_back();
  }
  return s;
}

template <typename T>
const char* numberNoun() {
  return std::is_integral_v<T> ? "an integer" : "a number";
}

}  // namespace cli_detail

// lo <= value <= hi (inclusive).
template <typename T>
CLI::Validator inRange(T lo, T hi) {
  return cli_detail::numberCheck<T>(
      static_cast<long double>(lo), static_cast<long double>(hi),
      std::string(cli_detail::numberNoun<T>()) + " in " + cli_detail::numberText(lo) +
          (std::is_integral_v<T> ? ".." : " to ") + cli_detail::numberText(hi));
}

// lo < value < hi (a real number).
inline CLI::Validator between(double lo, double hi) {
  return cli_detail::numberCheck<double>(lo, hi,
                                         "a number between " + cli_detail::numberText(lo) +
                                             " and " + cli_detail::numberText(hi) + " (exclusive)",
                                         /*exclusive=*/true);
}

// value >= lo.
template <typename T>
CLI::Validator atLeast(T lo) {
  return cli_detail::numberCheck<T>(
      static_cast<long double>(lo), static_cast<long double>(std::numeric_limits<T>::max()),
      std::string(cli_detail::numberNoun<T>()) + " >= " + cli_detail::numberText(lo));
}

// value > 0 (a real number: integral options use atLeast(1)).
inline CLI::Validator positive() {
  return cli_detail::numberCheck<double>(std::numeric_limits<long double>::denorm_min(),
                                         std::numeric_limits<long double>::max(),
                                         "a positive number");
}

// value >= 0 (a real number: integral options use atLeast(0)).
inline CLI::Validator nonNegative() {
  return cli_detail::numberCheck<double>(0.0L, std::numeric_limits<long double>::max(),
                                         "a number >= 0");
}

// A TCP port to connect to or listen on: 1..65535 (0 where `allowZero`, for
// "pick a free one").
inline CLI::Validator tcpPort(bool allowZero = false) {
  return inRange<int>(allowZero ? 0 : 1, 65535);
}

// Help shows every option's default (CLI11 captures it when the option is
// added), so help strings never type a default by hand. Call before adding
// options; subcommands inherit it.
inline void showDefaultsInHelp(CLI::App& app) {
  app.option_defaults()->always_capture_default();
}

// Requires one subcommand, shows defaults in help and adds --log-level
// (stored in `logLevel`).
inline void setUpToolApp(CLI::App& app, std::string& logLevel) {
  showDefaultsInHelp(app);
  app.require_subcommand(1);
  app.fallthrough();  // --log-level may follow the subcommand
  app.add_option("--log-level", logLevel, "trace, debug, info, warn, error, critical, off");
}

// Parses, sets up logging at `logLevel` and runs `body` (which returns the
// exit code), turning errors into exit codes as described above. Tools
// without subcommands call it directly.
template <typename Body>
int runFlatToolApp(const char* tool, CLI::App& app, int argc, char** argv,
                   const std::string& logLevel, Body&& body) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ValidationError& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool, e.what());
    return 1;
  } catch (const CLI::ConversionError& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool, e.what());
    return 1;
  } catch (const CLI::RequiredError& e) {
    // "A subcommand is required" says nothing about what went wrong: name
    // the word taken for a subcommand, or list the subcommands.
    if (app.get_require_subcommand_min() > 0 && app.get_subcommands().empty()) {
      std::string names;
      for (const CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; }))
        names += (names.empty() ? "" : ", ") + sub->get_name();
      std::string unknown;
      for (const std::string& word : app.remaining())
        if (!word.empty() && word[0] != '-') {
          unknown = word;
          break;
        }
      if (unknown.empty())
        std::fprintf(stderr, "%s: error: a subcommand is required: one of %s (see --help)\n", tool,
                     names.c_str());
      else
        std::fprintf(stderr, "%s: error: unknown subcommand '%s': expected one of %s\n", tool,
                     unknown.c_str(), names.c_str());
      return 2;
    }
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    initLogging(logLevel);
    return body();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool, e.what());
    return 1;
  }
}

// The same for a tool with subcommands (set up by setUpToolApp).
template <typename Dispatch>
int runToolApp(const char* tool, CLI::App& app, int argc, char** argv, const std::string& logLevel,
               Dispatch&& dispatch) {
  return runFlatToolApp(tool, app, argc, argv, logLevel, std::forward<Dispatch>(dispatch));
}

// The shared secret in the first line of a token file (trailing spaces and a
// CR removed). Throws InputError naming `option` and the file if it cannot be
// read or the line is empty.
inline std::string readTokenFile(const std::string& path, const char* option = "--token-file") {
  std::ifstream f(path);
  std::string token;
  if (!f || !std::getline(f, token)) throwInputError("{} {}: cannot read it", option, path);
  while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
  if (token.empty()) throwInputError("{} {}: the first line is empty", option, path);
  return token;
}

// Splits "a,b,c" into {"a", "b", "c"}; an empty string gives one empty item.
inline std::vector<std::string> splitCommaList(const std::string& text) {
  std::vector<std::string> out;
  for (size_t pos = 0; pos <= text.size();) {
    const size_t comma = text.find(',', pos);
    out.push_back(text.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos));
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return out;
}

// Adds --max-scene-triangles, bound to limits.maxTriangles, to a tool or
// subcommand that loads scene files.
inline void addSceneLimitsOption(CLI::App& app, SceneLimits& limits) {
  app.add_option("--max-scene-triangles", limits.maxTriangles,
                 "refuse scene files that make more triangles (built-in scenes are not limited)")
      ->capture_default_str()
      ->check(atLeast<uint64_t>(1));
}

// --ground auto|none|Y (common/world/static_world.h): the ground plane
// assumed under a scene whose objects stand on nothing. Checked at parse time.
inline void addGroundOption(CLI::App& app, GroundChoice& ground) {
  app.add_option_function<std::string>(
         "--ground", [&ground](const std::string& text) { ground = *parseGroundChoice(text); },
         "ground plane for free space, paths and the bake grid: auto (a plane at the lowest base "
         "of the objects when the scene has no surface under part of its footprint), none, or a "
         "height Y in metres (file coordinates)")
      ->default_str("auto")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            return parseGroundChoice(text)
                       ? std::string()
                       : "expected auto, none or a height in metres, got '" + text + "'";
          },
          "auto|none|Y"));
}

// --lighting-cache DIR: where baked lighting is kept (lighting_cache.h);
// "none" bakes at every start. `dir` starts as the default directory.
inline void addLightingCacheOption(CLI::App& app, std::filesystem::path& dir) {
  dir = defaultLightingCacheDir();
  app.add_option_function<std::string>(
         "--lighting-cache",
         [&dir](const std::string& text) {
           dir = text == "none" ? std::filesystem::path() : std::filesystem::path(text);
         },
         "directory for baked lighting, read back on later starts; none: bake every time")
      ->default_str(dir.string());
}

}  // namespace vistream
