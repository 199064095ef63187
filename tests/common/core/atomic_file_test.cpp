#include "common/core/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

using testing::TempDir;

std::string contentsOf(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

// A content whose every byte says which writer made it, so a torn or mixed
// file is recognisable.
std::string wholeContent(int writer, size_t bytes) {
  return std::string(bytes, char('a' + writer));
}

bool isWholeContent(const std::string& s, size_t bytes) {
  return s.size() == bytes && s.find_first_not_of(s[0]) == std::string::npos;
}

TEST(AtomicFile, ACommittedFileHoldsExactlyWhatWasWrittenAndNothingElseIsLeft) {
  const TempDir dir;
  AtomicFile file(dir / "out.bin");
  file.write(std::string_view("head,"));
  const uint8_t tail[3] = {'x', 0, 'y'};
  file.write(tail);
  file.commit();
  EXPECT_EQ(contentsOf(dir / "out.bin"), std::string("head,x\0y", 8));
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"out.bin"});
}

TEST(AtomicFile, AWriterDestroyedWithoutCommitLeavesTheOldFileAndNoTemporary) {
  const TempDir dir;
  dir.write("out.txt", "old");
  {
    AtomicFile file(dir / "out.txt");
    file.write(std::string_view("new but unfinished"));
    EXPECT_TRUE(std::filesystem::exists(file.temporary()));
  }
  EXPECT_EQ(contentsOf(dir / "out.txt"), "old");
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFile, ASyncedCommitReplacesTheOldFile) {
  const TempDir dir;
  dir.write("out.txt", "old contents, longer than the new");
  writeFileAtomically(dir / "out.txt", "new", Durability::Synced);
  EXPECT_EQ(contentsOf(dir / "out.txt"), "new");
}

TEST(AtomicFile, TemporaryNamesAreUniquePerCallAndNameHostAndProcess) {
  std::set<std::string> names;
  for (int i = 0; i < 1000; ++i) names.insert(uniqueTemporaryBeside("/x/cache.light").string());
  EXPECT_EQ(names.size(), 1000u);
  char host[256] = {};
  ASSERT_EQ(::gethostname(host, sizeof(host) - 1), 0);
  const std::string one = *names.begin();
  EXPECT_EQ(one.rfind("/x/cache.light.tmp.", 0), 0u) << one;
  EXPECT_NE(one.find("." + std::to_string(::getpid()) + "."), std::string::npos) << one;
}

TEST(AtomicFile, AnUnwritableDirectoryIsAnInputErrorNamingTheFile) {
  const TempDir dir;
  const std::string message =
      testing::inputErrorOf([&] { writeFileAtomically(dir / "missing" / "out.txt", "x"); });
  EXPECT_NE(message.find("missing/out.txt"), std::string::npos) << message;
  EXPECT_NE(message.find("cannot open for writing"), std::string::npos) << message;
}

// The case that made the class: several writers (threads here, pods on one
// volume in production) replace the same file at once. A reader never sees a
// torn or mixed file, and no temporary is left behind.
TEST(AtomicFile, ConcurrentWritersOfOneFileNeverTearIt) {
  const TempDir dir;
  const auto target = dir / "shared.light";
  constexpr size_t kBytes = 256 * 1024;
  writeFileAtomically(target, wholeContent(0, kBytes));
  std::atomic<bool> done{false};
  std::atomic<int> torn{0}, reads{0};
  std::thread reader([&] {
    while (!done) {
      if (!isWholeContent(contentsOf(target), kBytes)) ++torn;
      ++reads;
    }
  });
  std::vector<std::thread> writers;
  for (int w = 1; w <= 4; ++w)
    writers.emplace_back([&, w] {
      for (int i = 0; i < 20; ++i) writeFileAtomically(target, wholeContent(w, kBytes));
    });
  for (auto& t : writers) t.join();
  done = true;
  reader.join();
  EXPECT_EQ(torn.load(), 0) << "of " << reads.load() << " reads";
  EXPECT_GT(reads.load(), 0);
  EXPECT_TRUE(isWholeContent(contentsOf(target), kBytes));
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"shared.light"});
}

// Processes with one pid each (as every container's pid 1 would be, were they
// on one host) still get distinct temporaries: the counter and random word
// differ. Here: forked children, each writing many times.
TEST(AtomicFile, ConcurrentProcessesWritingOneFileLeaveOneWholeFile) {
  const TempDir dir;
  const auto target = dir / "shared.bin";
  constexpr size_t kBytes = 64 * 1024;
  std::vector<pid_t> children;
  for (int w = 0; w < 3; ++w) {
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      try {
        for (int i = 0; i < 30; ++i) writeFileAtomically(target, wholeContent(w, kBytes));
      } catch (...) {
        ::_exit(1);
      }
      ::_exit(0);
    }
    children.push_back(pid);
  }
  for (const pid_t pid : children) {
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  }
  EXPECT_TRUE(isWholeContent(contentsOf(target), kBytes));
  EXPECT_EQ(dir.filenames(), std::vector<std::string>{"shared.bin"});
}

}  // namespace
}  // namespace vistream
