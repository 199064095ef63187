// A file that appears whole or not at all.
//
// Bytes go to a temporary file beside the target, named uniquely for this
// host, process and object (NAME.tmp.HOST.PID.COUNTER.WORD: hostname, pid, a
// per-process counter and a random word; NAME is cut so the whole stays
// within NAME_MAX), so writers on several machines sharing one volume, or
// several containers that all run as pid 1, never write into each other's
// temporary. commit() flushes (and with Durability::Synced, fsyncs) the
// temporary and renames it over the target, which POSIX makes atomic within a
// file system: readers see the old file or the new one, never a torn one;
// Synced also fsyncs the directory (where the file system can), so the
// rename survives a crash; if that fails, commit() throws with the target
// already replaced. An object
// destroyed without commit() removes its temporary and leaves the target as it
// was. A process killed mid-write cannot: its temporary stays until a later
// process writing into the same directory removes it as stale
// (removeStaleTemporaries).
// The file gets mode 0666 less the umask.
//
// Errors: every failure (open, write, flush, rename) throws InputError naming
// the file and the system's reason. Not thread-safe; one writer per object.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string_view>

namespace vistream {

enum class Durability {
  Flushed,  // written to the OS before the rename (survives the process)
  Synced,   // also fsync'ed before the rename (survives the machine)
};

class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path target);
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile();

  void write(std::span<const uint8_t> bytes);
  void write(std::string_view text) {
    write({reinterpret_cast<const uint8_t*>(text.data()), text.size()});
  }
  // Makes the target hold exactly what was written. Call once.
  void commit(Durability durability = Durability::Flushed);

  const std::filesystem::path& target() const { return target_; }
  const std::filesystem::path& temporary() const { return temporary_; }

 private:
  std::filesystem::path target_;
  std::filesystem::path temporary_;
  int fd_ = -1;
};

// Writes all of `bytes` to the open descriptor `fd`, retrying short writes
// and EINTR; throws InputError naming `name` on failure.
void writeAllTo(int fd, std::span<const uint8_t> bytes, const std::filesystem::path& name);

// The temporary name AtomicFile uses for `target`: unique per call.
std::filesystem::path uniqueTemporaryBeside(const std::filesystem::path& target);

// Removes the stale temporaries in `target`'s directory (of any target;
// names of exactly the temporary's form, NAME.tmp.HOST.PID.COUNTER.WORD):
// those a process of this host left that no longer runs, untouched for an
// hour, and those of any host untouched for 24 hours (a writer that long
// silent is taken as gone). Never this process's own. AtomicFile calls it
// before it writes, once per directory and process (later calls return 0);
// returns how many it removed.
size_t removeStaleTemporaries(const std::filesystem::path& target);

// One-shot forms.
void writeFileAtomically(const std::filesystem::path& target, std::span<const uint8_t> bytes,
                         Durability durability = Durability::Flushed);
void writeFileAtomically(const std::filesystem::path& target, std::string_view text,
                         Durability durability = Durability::Flushed);

}  // namespace vistream
