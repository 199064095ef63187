// `vistream-pvs impostors`: point-based impostors of view cells (Wimmer
// 2001, chapter 5; server/impostor/). One cell's impostors baked and
// reported (--cell), or every cell of a baked PVS database into an impostor
// database (--db, --out).
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <optional>
#include <string>

#include "common/core/box.h"
#include "common/scene/scene_loader.h"

namespace vistream {

class PvsDatabase;
struct ImpostorBakeReport;

class ImpostorCommand {
 public:
  // Adds the subcommand to `app`; `limits` is the tool's shared scene limit.
  ImpostorCommand(CLI::App& app, SceneLimits& limits);
  ~ImpostorCommand();

  bool chosen() const;
  // Runs it (after parsing). Returns the exit code; throws InputError on bad input.
  int run();

 private:
  struct Arguments;
  std::string settingsJson() const;
  int bakeDatabase(const Scene& scene, const PvsDatabase& pvs,
                   const std::optional<Box3d>& fileCells);
  ImpostorBakeReport bakeShardOf(const Scene& scene, const PvsDatabase& pvs,
                                 const std::optional<Box3d>& fileCells, uint32_t shardIndex,
                                 uint32_t shardCount, const std::string& out, bool progress) const;
  CLI::App* sub_ = nullptr;
  SceneLimits& limits_;
  std::unique_ptr<Arguments> a_;
};

}  // namespace vistream
