// The shape every vistream command-line tool shares: one CLI11 app with
// subcommands, a --log-level that may come before or after the subcommand,
// and one boundary where errors become exit codes (0 success, 1 bad input
// with "tool: error: ..." on stderr, 2 bad usage).
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "common/core/error.h"
#include "common/core/log.h"
#include "common/scene/scene_loader.h"

namespace vistream {

// Requires one subcommand and adds --log-level (stored in `logLevel`).
inline void setUpToolApp(CLI::App& app, std::string& logLevel) {
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
      ->capture_default_str();
}

}  // namespace vistream
