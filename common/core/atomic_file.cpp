#include "common/core/atomic_file.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cerrno>
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

}  // namespace

std::filesystem::path uniqueTemporaryBeside(const std::filesystem::path& target) {
  static const std::string host = hostName();
  static std::atomic<uint64_t> counter{0};
  thread_local std::mt19937_64 random{std::random_device{}()};
  return target.string() +
         fmt::format(".tmp.{}.{}.{}.{:08x}", host, ::getpid(), counter++, uint32_t(random()));
}

AtomicFile::AtomicFile(std::filesystem::path target)
    : target_(std::move(target)), temporary_(uniqueTemporaryBeside(target_)) {
  fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
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
