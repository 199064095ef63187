#include "common/core/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <random>
#include <set>
#include <string>

#include "common/core/check.h"
#include "common/core/error.h"

namespace vistream {

namespace {

std::string hostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "host";
  std::string out;
  for (const char* c = name; *c; ++c)  // keep the name safe inside a file name
    out += (std::isalnum(static_cast<unsigned char>(*c)) || *c == '-') ? *c : '_';
  return out.empty() ? "host" : out;
}

// The first part of every temporary's name for `target`: its file name, cut
// so that the whole temporary name stays within NAME_MAX (255 bytes), then
// ".tmp.".
std::string temporaryPrefix(const std::filesystem::path& target) {
  // ".tmp." + host (at most 40) "." pid (at most 10) "." counter (at most 20)
  // "." word (8).
  constexpr size_t kSuffix = 5 + 40 + 1 + 10 + 1 + 20 + 1 + 8;
  std::string name = target.filename().string();
  if (name.size() > 255 - kSuffix) name.resize(255 - kSuffix);
  return name + ".tmp.";
}

std::string shortHostName() {
  static const std::string host = [] {
    std::string h = hostName();
    if (h.size() > 40) h.resize(40);
    return h;
  }();
  return host;
}

bool allOf(const std::string& s, int (*is)(int)) {
  return !s.empty() &&
         std::all_of(s.begin(), s.end(), [&](char c) { return is(static_cast<unsigned char>(c)); });
}

// The parts of a temporary's name after its prefix, HOST.PID.COUNTER.WORD;
// false for a name of any other form (a user's file that merely starts with
// the prefix).
bool parseTemporary(const std::string& rest, std::string& host, long& pid) {
  const size_t word = rest.rfind('.');
  if (word == std::string::npos || word == 0) return false;
  const size_t counter = rest.rfind('.', word - 1);
  if (counter == std::string::npos || counter == 0) return false;
  const size_t pidAt = rest.rfind('.', counter - 1);
  if (pidAt == std::string::npos || pidAt == 0) return false;
  const std::string w = rest.substr(word + 1), c = rest.substr(counter + 1, word - counter - 1),
                    p = rest.substr(pidAt + 1, counter - pidAt - 1);
  if (w.size() != 8 || !allOf(w, ::isxdigit) || !allOf(c, ::isdigit) || !allOf(p, ::isdigit) ||
      p.size() > 10)
    return false;
  host = rest.substr(0, pidAt);
  pid = std::strtol(p.c_str(), nullptr, 10);
  return true;
}

// Whether `name`, a temporary of some writer, is stale: left by a process of
// this host that no longer runs and untouched for an hour (the hour guards
// against a live writer in another PID namespace under the same host name),
// or (any host) untouched for a day.
bool staleTemporary(const std::filesystem::path& path, const std::string& name,
                    const std::string& prefix) {
  std::string host;
  long pid = 0;
  if (!parseTemporary(name.substr(prefix.size()), host, pid)) return false;
  std::error_code ec;
  const auto written = std::filesystem::last_write_time(path, ec);
  if (ec) return false;
  const auto age = std::filesystem::file_time_type::clock::now() - written;
  if (age > std::chrono::hours(24)) return true;
  return host == shortHostName() && age > std::chrono::hours(1) && pid > 0 &&
         pid != long(::getpid()) && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH;
}

}  // namespace

std::filesystem::path uniqueTemporaryBeside(const std::filesystem::path& target) {
  static std::atomic<uint64_t> counter{0};
  // Reseeded in a new process: forked children inherit the parent's state.
  thread_local std::mt19937_64 random{std::random_device{}()};
  thread_local pid_t seededIn = ::getpid();
  const pid_t pid = ::getpid();
  if (pid != seededIn) {
    random.seed(std::random_device{}());
    seededIn = pid;
  }
  return target.parent_path() /
         (temporaryPrefix(target) +
          fmt::format("{}.{}.{}.{:08x}", shortHostName(), pid, counter++, uint32_t(random())));
}

size_t removeStaleTemporaries(const std::filesystem::path& target) {
  const std::filesystem::path dir =
      target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
  {
    // Once per directory and process: writing many files into one directory
    // (a walk's frames) would otherwise scan it once per file.
    static std::mutex mutex;
    static std::set<std::string> swept;
    const std::lock_guard<std::mutex> lock(mutex);
    std::error_code ec;
    const std::filesystem::path key = std::filesystem::weakly_canonical(dir, ec);
    if (!swept.insert((ec ? dir : key).string()).second) return 0;
  }
  size_t removed = 0;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const size_t at = name.rfind(".tmp.");
    if (at == std::string::npos || !staleTemporary(it->path(), name, name.substr(0, at + 5)))
      continue;
    std::error_code ignored;
    removed += std::filesystem::remove(it->path(), ignored);
  }
  return removed;
}

AtomicFile::AtomicFile(std::filesystem::path target)
    : target_(std::move(target)), temporary_(uniqueTemporaryBeside(target_)) {
  removeStaleTemporaries(target_);
  // 0666 less the umask, as for any file the user creates.
  fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0)
    throwInputError("{}: cannot open for writing: {}", temporary_.string(), std::strerror(errno));
}

AtomicFile::~AtomicFile() {
  if (fd_ < 0) return;
  ::close(fd_);
  std::error_code ignored;
  std::filesystem::remove(temporary_, ignored);
}

void writeAllTo(int fd, std::span<const uint8_t> bytes, const std::filesystem::path& name) {
  const uint8_t* p = bytes.data();
  size_t n = bytes.size();
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      throwInputError("{}: write failed: {}", name.string(), std::strerror(errno));
    }
    p += w;
    n -= size_t(w);
  }
}

void AtomicFile::write(std::span<const uint8_t> bytes) {
  VS_CHECK(fd_ >= 0);  // write after commit
  writeAllTo(fd_, bytes, temporary_);
}

void AtomicFile::commit(Durability durability) {
  VS_CHECK(fd_ >= 0);  // commit twice
  if (durability == Durability::Synced && ::fsync(fd_) != 0)
    throwInputError("{}: cannot flush to disk: {}", temporary_.string(), std::strerror(errno));
  const int fd = fd_;
  fd_ = -1;
  const bool closed = ::close(fd) == 0;
  std::error_code ec;
  if (!closed) {
    const std::string reason = std::strerror(errno);
    std::filesystem::remove(temporary_, ec);
    throwInputError("{}: cannot close: {}", temporary_.string(), reason);
  }
  std::filesystem::rename(temporary_, target_, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(temporary_, ignored);
    throwInputError("{}: cannot rename into place: {}", target_.string(), ec.message());
  }
  if (durability == Durability::Synced) {
    // The rename itself survives a crash only once the directory is synced.
    const std::filesystem::path dir =
        target_.parent_path().empty() ? std::filesystem::path(".") : target_.parent_path();
    // Some file systems cannot sync a directory (EINVAL): nothing more to do there.
    const int dirFd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    const bool synced = dirFd >= 0 && (::fsync(dirFd) == 0 || errno == EINVAL);
    const std::string reason = synced ? "" : std::strerror(errno);
    if (dirFd >= 0) ::close(dirFd);
    if (!synced) throwInputError("{}: cannot sync the directory: {}", dir.string(), reason);
  }
}

void writeFileAtomically(const std::filesystem::path& target, std::span<const uint8_t> bytes,
                         Durability durability) {
  AtomicFile file(target);
  file.write(bytes);
  file.commit(durability);
}

void writeFileAtomically(const std::filesystem::path& target, std::string_view text,
                         Durability durability) {
  AtomicFile file(target);
  file.write(text);
  file.commit(durability);
}

}  // namespace vistream
