#include "server/cmd/mpi_bake.h"

#include <fmt/format.h>
#include <mpi.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <vector>

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

int runMpiBake(const std::string& out,
               const std::function<MpiShardCounts(const MpiShard&)>& bakeShard,
               const std::function<void(const std::vector<std::string>& shards,
                                        const MpiShardCounts& all)>& merge) {
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
      merge(shards, MpiShardCounts{sums[0], sums[1]});
      for (const std::string& s : shards) std::filesystem::remove(s);
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
