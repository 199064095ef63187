// `vistream-pvs bake --mpi`: the bake spread over the ranks of an MPI job
// (OpenMPI's mpirun, or any launcher of MPI_COMM_WORLD), never a cluster of
// our own.
//
// Every rank bakes shard `rank` of `size` (the bake's --shard i/n) into
// OUT.shard-<rank>-of-<size>, with that file's journal beside it; when every
// rank has finished, rank 0 merges the shards into OUT (mergePvsDatabases:
// the same bytes as one process baking every cell) and removes them. A rank
// that is killed takes the job down with it (mpirun's rule); run the same
// command again and every rank resumes its shard from its journal.
//
// Threads: with --threads 0 each rank takes its share of its machine's
// cores (the cores over the ranks on that machine), so two ranks on one
// machine do not oversubscribe it.
//
// Errors: a rank whose bake fails prints its error (prefixed with its rank)
// and every rank exits with 1 once all have finished; rank 0 merges only
// when all shards are complete.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace vistream {

// "i/n" with 0 <= i < n (a bake's --shard); throws InputError naming `option`.
std::pair<uint32_t, uint32_t> parseShard(const std::string& text, const char* option = "--shard");

struct MpiShard {
  unsigned rank = 0, size = 1;
  unsigned localRanks = 1;  // ranks on this rank's machine
  std::string out;          // this rank's shard file
};

// What a rank's shard did, summed over the ranks for rank 0's report.
struct MpiShardCounts {
  uint64_t cells = 0, resumed = 0;
};

// Runs the MPI job described above: `bakeShard` bakes one shard (it may
// throw), `merge` (rank 0 only) merges the shard files into `out` and
// returns the cells it holds; rank 0 then prints the job's report (`what`
// baked, cells, those resumed, time), as JSON with `asJson`. Returns the
// process's exit code. Initializes and finalizes MPI.
int runMpiBake(const std::string& out, const char* what, bool asJson,
               const std::function<MpiShardCounts(const MpiShard&)>& bakeShard,
               const std::function<size_t(const std::vector<std::string>& shards)>& merge);

}  // namespace vistream
