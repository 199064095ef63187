// Runs one of the project's executables (from VISTREAM_BIN_DIR) with
// arguments and captures its exit status, stdout and stderr.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace vistream::testing {

struct ToolRun {
  int status = -1;  // exit code, -1 if the tool did not exit normally
  std::string out;
  std::string err;
};

inline ToolRun runTool(const std::string& tool, const std::string& args) {
  static int counter = 0;
  const std::filesystem::path errFile =
      std::filesystem::temp_directory_path() /
      ("vistream_tool_err_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
  const std::string cmd =
      std::string(VISTREAM_BIN_DIR) + "/" + tool + " " + args + " 2>" + errFile.string();
  ToolRun r;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  const int st = ::pclose(pipe);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  std::ifstream e(errFile);
  r.err.assign(std::istreambuf_iterator<char>(e), {});
  std::filesystem::remove(errFile);
  return r;
}

// One executable bound to its name: `tool(args)` is runTool(tool.name, args).
struct Tool {
  std::string name;
  ToolRun operator()(const std::string& args) const { return runTool(name, args); }
};

}  // namespace vistream::testing
