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
  struct RestoreUmask {
    mode_t saved = ::umask(0);
    ~RestoreUmask() { ::umask(saved); }
  } restore;
  writeFileAtomically(dir / "open.txt", "x");
  ::umask(0077);
  writeFileAtomically(dir / "private.txt", "x");
  EXPECT_EQ(std::filesystem::status(dir / "open.txt").permissions(), std::filesystem::perms(0666));
  EXPECT_EQ(std::filesystem::status(dir / "private.txt").permissions(),
            std::filesystem::perms(0600));
}

// A writer killed mid-write leaves its temporary; a later process writing
// into the directory removes it once its process is gone and it is an hour
// old (same host), or a day old (any host), and keeps every other: younger
// ones, ones of running processes, and files that only look like temporaries.
TEST(AtomicFile, StaleTemporariesOfKilledWritersAreRemovedByALaterWriter) {
  const TempDir dir;
  const auto target = dir / "pvs.db";
  const auto now = std::filesystem::file_time_type::clock::now();
  auto fork_writer = [&](const std::filesystem::path& t) {
    const pid_t child = ::fork();
    if (child == 0) {
      AtomicFile file(t);
      file.write("half a database");
      ::_exit(0);  // killed: no destructor, no commit
    }
    int status = 0;
    EXPECT_EQ(::waitpid(child, &status, 0), child);
    return child;
  };
  const pid_t killedLongAgo = fork_writer(target);
  const pid_t killedJustNow = fork_writer(dir / "other.db");
  std::vector<std::string> names = dir.filenames();
  ASSERT_EQ(names.size(), 2u) << "the children's temporaries";
  for (const std::string& name : names) {
    if (name.find("." + std::to_string(killedLongAgo) + ".") == std::string::npos) continue;
    std::filesystem::last_write_time(dir / name, now - std::chrono::hours(2));
  }
  // Another host's, written now and two days ago; ours, of a running process
  // (pid 1 always runs), two hours old; a user's file that only starts like
  // a temporary, two days old.
  const std::string ownHost =
      uniqueTemporaryBeside(target).filename().string().substr(std::string("pvs.db.tmp.").size());
  const std::string host = ownHost.substr(0, ownHost.find('.'));
  const auto otherHostFresh = dir / "pvs.db.tmp.elsewhere.7.0.0000abcd";
  const auto otherHostOld = dir / "pvs.db.tmp.elsewhere.8.0.0000abcd";
  const auto running = dir / ("pvs.db.tmp." + host + ".1.0.0000abcd");
  const auto usersFile = dir / "pvs.db.tmp.backup";
  for (const auto& p : {otherHostFresh, otherHostOld, running, usersFile}) std::ofstream(p) << "x";
  std::filesystem::last_write_time(otherHostOld, now - std::chrono::hours(48));
  std::filesystem::last_write_time(running, now - std::chrono::hours(2));
  std::filesystem::last_write_time(usersFile, now - std::chrono::hours(48));
  writeFileAtomically(target, "whole");
  std::vector<std::string> kept = {"pvs.db", running.filename().string(),
                                   otherHostFresh.filename().string(),
                                   usersFile.filename().string()};
  for (const std::string& name : names)
    if (name.find("." + std::to_string(killedJustNow) + ".") != std::string::npos)
      kept.push_back(name);  // dead, but not an hour old
  std::sort(kept.begin(), kept.end());
  EXPECT_EQ(dir.filenames(), kept);
  EXPECT_EQ(contentsOf(target), "whole");
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
