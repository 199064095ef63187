#include "common/core/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
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
  std::string safeHost;
  for (const char* c = host; *c; ++c)
    safeHost += std::isalnum(static_cast<unsigned char>(*c)) || *c == '-' ? *c : '_';
  safeHost.resize(std::min<size_t>(safeHost.size(), 40));
  const std::string one = *names.begin();
  EXPECT_EQ(one.rfind("/x/cache.light.tmp." + safeHost + "." + std::to_string(::getpid()) + ".", 0),
            0u)
      << one;
}

TEST(AtomicFile, ATemporaryOfALongNameStaysWithinNameMax) {
  const TempDir dir;
  const std::string longName(250, 'n');
  EXPECT_LE(uniqueTemporaryBeside(dir / longName).filename().string().size(), 255u);
  writeFileAtomically(dir / longName, "whole");
  EXPECT_EQ(contentsOf(dir / longName), "whole");
}

TEST(AtomicFile, TheFileModeIsTheUsersUmaskAppliedTo0666) {
  const TempDir dir;
  const mode_t saved = ::umask(0);
  writeFileAtomically(dir / "open.txt", "x");
  ::umask(0077);
  writeFileAtomically(dir / "private.txt", "x");
  ::umask(saved);
  EXPECT_EQ(std::filesystem::status(dir / "open.txt").permissions(), std::filesystem::perms(0666));
  EXPECT_EQ(std::filesystem::status(dir / "private.txt").permissions(),
            std::filesystem::perms(0600));
}

// A writer killed mid-write leaves its temporary; the next writer of the same
// target removes it when its process is gone (same host) or it has not been
// touched for a day (any host), and keeps every other.
TEST(AtomicFile, StaleTemporariesOfKilledWritersAreRemovedByTheNextWriter) {
  const TempDir dir;
  const auto target = dir / "pvs.db";
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    AtomicFile file(target);
    file.write("half a database");
    ::_exit(0);  // killed: no destructor, no commit
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_EQ(dir.filenames().size(), 1u) << "the child's temporary";
  EXPECT_NE(dir.filenames()[0].find("." + std::to_string(child) + "."), std::string::npos);
  // Another host's, written now and two days ago; ours, of a running process
  // (pid 1 always runs).
  const auto otherHostFresh = dir / "pvs.db.tmp.elsewhere.7.0.0000abcd";
  const auto otherHostOld = dir / "pvs.db.tmp.elsewhere.8.0.0000abcd";
  const std::string ownHost =
      uniqueTemporaryBeside(target).filename().string().substr(std::string("pvs.db.tmp.").size());
  const auto running =
      dir / ("pvs.db.tmp." + ownHost.substr(0, ownHost.find('.')) + ".1.0.0000abcd");
  for (const auto& p : {otherHostFresh, otherHostOld, running}) std::ofstream(p) << "x";
  std::filesystem::last_write_time(
      otherHostOld, std::filesystem::file_time_type::clock::now() - std::chrono::hours(48));
  writeFileAtomically(target, "whole");
  std::vector<std::string> kept = {"pvs.db", running.filename().string(),
                                   otherHostFresh.filename().string()};
  std::sort(kept.begin(), kept.end());
  EXPECT_EQ(dir.filenames(), kept);
  EXPECT_EQ(contentsOf(target), "whole");
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

// Several processes writing one file, each many times: their temporaries
// differ by pid (forked children inherit the counter and the random
// generator, which reseeds itself in a new process).
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
