#include "server/cmd/mpi_bake.h"

#include <fmt/format.h>
#include <mpi.h>
#include <spdlog/spdlog.h>

#include <charconv>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <vector>

#include "common/core/error.h"
#include "common/core/timer.h"

namespace vistream {
namespace {

// MPI_Init_thread and MPI_Finalize around a scope; only the main thread
// calls MPI (the bake's worker threads never do).
struct MpiScope {
  MpiScope() {
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  }
  ~MpiScope() { MPI_Finalize(); }
  MpiScope(const MpiScope&) = delete;
  MpiScope& operator=(const MpiScope&) = delete;
};

unsigned ranksOnThisMachine() {
  MPI_Comm local = MPI_COMM_NULL;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &local);
  int n = 1;
  MPI_Comm_size(local, &n);
  MPI_Comm_free(&local);
  return unsigned(std::max(1, n));
}

}  // namespace

std::pair<uint32_t, uint32_t> parseShard(const std::string& text, const char* option) {
  const size_t slash = text.find('/');
  const char* end = text.data() + text.size();
  const char* mid = slash == std::string::npos ? end : text.data() + slash;
  uint32_t i = 0, n = 0;
  const auto r1 = std::from_chars(text.data(), mid, i);
  const bool ok = r1.ec == std::errc() && r1.ptr == mid && mid != end &&
                  std::from_chars(mid + 1, end, n).ptr == end && n > 0 && i < n;
  if (!ok) throwInputError("{}: expected i/n with 0 <= i < n, got '{}'", option, text);
  return {i, n};
}

int runMpiBake(const std::string& out, const char* what, bool asJson,
               const std::function<MpiShardCounts(const MpiShard&)>& bakeShard,
               const std::function<size_t(const std::vector<std::string>& shards)>& merge) {
  Stopwatch clock;
  MpiScope scope;
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MpiShard shard;
  shard.rank = unsigned(rank);
  shard.size = unsigned(size);
  shard.localRanks = ranksOnThisMachine();
  std::vector<std::string> shards;
  for (int r = 0; r < size; ++r) shards.push_back(fmt::format("{}.shard-{}-of-{}", out, r, size));
  shard.out = shards[size_t(rank)];
  int ok = 1;
  MpiShardCounts mine;
  try {
    mine = bakeShard(shard);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vistream-pvs: error: rank %d of %d: %s\n", rank, size, e.what());
    ok = 0;
  }
  int allOk = 0;
  MPI_Allreduce(&ok, &allOk, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  if (!allOk) {
    if (rank == 0 && ok)
      std::fprintf(stderr, "vistream-pvs: error: a rank's shard failed; %s not written\n",
                   out.c_str());
    return 1;
  }
  const uint64_t counts[2] = {mine.cells, mine.resumed};
  uint64_t sums[2] = {0, 0};
  MPI_Reduce(counts, sums, 2, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
  int merged = 1;
  if (rank == 0) {
    try {
      const size_t cells = merge(shards);
      for (const std::string& s : shards) std::filesystem::remove(s);
      if (asJson)
        std::cout << nlohmann::json{{"out", out},
                                    {"ranks", size},
                                    {"cells", cells},
                                    {"resumed_cells", sums[1]},
                                    {"computed_cells", sums[0] - sums[1]},
                                    {"time_ms", clock.ms()}}
                         .dump(2)
                  << "\n";
      else
        fmt::print(
            "baked {} on {} MPI ranks -> {}: {} cells ({} resumed from journals) in "
            "{:.1f} s\n",
            what, size, out, cells, sums[1], clock.ms() / 1000.0);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "vistream-pvs: error: merging the shards into %s: %s\n", out.c_str(),
                   e.what());
      merged = 0;
    }
  }
  MPI_Bcast(&merged, 1, MPI_INT, 0, MPI_COMM_WORLD);
  return merged ? 0 : 1;
}

}  // namespace vistream
