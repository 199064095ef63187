// Expectations shared by the command-line tool tests: a bad argument fails
// with exit status 1 and an error naming it, and help shows the defaults
// captured from the code. Each check runs the tool through runTool
// (run_tool.h) and reports through GoogleTest, with the tool and the
// arguments as a SCOPED_TRACE.
#pragma once

#include <gtest/gtest.h>

#include <initializer_list>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "tests/common/support/run_tool.h"

namespace vistream::testing {

// Where the expected mention stands in the tool's stderr.
enum class MentionAt {
  Start,     // stderr begins with "TOOL: error: MENTION"
  Anywhere,  // stderr contains "TOOL: error: MENTION"
};

// One bad case: the arguments it adds to RefusedCommand::common and what its
// error must mention.
using BadArguments = std::pair<std::string, std::string>;

// A tool and the arguments shared by a list of bad cases.
struct RefusedCommand {
  std::string tool{};               // as "vistream-scene"
  std::string common{};             // arguments every case starts with
  MentionAt at = MentionAt::Start;  // where "TOOL: error: MENTION" must stand
  std::string afterName{};          // with expectEachOptionNamed: what follows the name
  // A file named in `common` that does not exist; if not empty, no error may
  // mention it (the bad argument was checked before the tool opened it).
  std::string unopened{};
};

// Runs `cmd.tool` with `cmd.common` and each case's arguments and expects
// exit status 1 and "TOOL: error: MENTION" where `cmd.at` says.
inline void expectEachRefused(const RefusedCommand& cmd, std::span<const BadArguments> cases) {
  for (const auto& [args, mention] : cases) {
    const std::string line = cmd.common + " " + args;
    SCOPED_TRACE(cmd.tool + " " + line);
    const ToolRun r = runTool(cmd.tool, line);
    EXPECT_EQ(r.status, 1) << r.err;
    const std::string expected = cmd.tool + ": error: " + mention;
    if (cmd.at == MentionAt::Start) {
      EXPECT_EQ(r.err.rfind(expected, 0), 0u) << r.err;
    } else {
      EXPECT_NE(r.err.find(expected), std::string::npos) << r.err;
    }
    if (!cmd.unopened.empty()) {
      EXPECT_EQ(r.err.find(cmd.unopened), std::string::npos) << "checked after opening: " << r.err;
    }
  }
}

// expectEachRefused for cases that are one option and its value (as
// "--frames -5"), whose error must name the option followed by
// `cmd.afterName` ("--frames:" with afterName ":").
inline void expectEachOptionNamed(const RefusedCommand& cmd,
                                  std::initializer_list<std::string> badOptions) {
  std::vector<BadArguments> cases;
  for (const std::string& bad : badOptions)
    cases.emplace_back(bad, bad.substr(0, bad.find(' ')) + cmd.afterName);
  expectEachRefused(cmd, cases);
}

// Expects `run` to have ended with exit status `status` and `text`
// somewhere in its stderr.
inline void expectFailedSaying(const ToolRun& run, int status, const std::string& text) {
  EXPECT_EQ(run.status, status) << run.err;
  EXPECT_NE(run.err.find(text), std::string::npos) << run.err;
}

// Runs `tool --help` and expects exit status 0, no default typed by hand into
// a help string (CLI11 prints those as "(default ...)") and `capturedDefault`
// (as "=7070", the form CLI11 gives a captured default) in the text.
inline void expectHelpShowsCapturedDefaults(const std::string& tool,
                                            const std::string& capturedDefault) {
  SCOPED_TRACE(tool);
  const ToolRun help = runTool(tool, "--help");
  EXPECT_EQ(help.status, 0);
  EXPECT_EQ(help.out.find("(default"), std::string::npos) << help.out;
  EXPECT_NE(help.out.find(capturedDefault), std::string::npos) << help.out;
}

}  // namespace vistream::testing
