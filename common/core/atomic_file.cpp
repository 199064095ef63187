#include "common/core/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <random>
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
  constexpr size_t kSuffix = 64;  // ".tmp." + host (at most 40 here) + pid + counter + word
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

// Whether `name`, a temporary of some writer, is stale: left by a process of
// this host that no longer runs, or (any host) untouched for a day.
bool staleTemporary(const std::filesystem::path& path, const std::string& name,
                    const std::string& prefix) {
  // name = prefix + host "." pid "." counter "." word
  const std::string rest = name.substr(prefix.size());
  const std::string host = shortHostName();
  if (rest.rfind(host + ".", 0) == 0) {
    const std::string afterHost = rest.substr(host.size() + 1);
    char* end = nullptr;
    const long pid = std::strtol(afterHost.c_str(), &end, 10);
    if (end != afterHost.c_str() && *end == '.' && pid > 0 && pid != long(::getpid()) &&
        ::kill(pid_t(pid), 0) != 0 && errno == ESRCH)
      return true;
  }
  std::error_code ec;
  const auto written = std::filesystem::last_write_time(path, ec);
  return !ec && std::filesystem::file_time_type::clock::now() - written > std::chrono::hours(24);
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
  const std::string prefix = temporaryPrefix(target);
  const std::filesystem::path dir =
      target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
  size_t removed = 0;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(prefix, 0) != 0 || !staleTemporary(it->path(), name, prefix)) continue;
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
    const int dirFd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    const bool synced = dirFd >= 0 && ::fsync(dirFd) == 0;
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
