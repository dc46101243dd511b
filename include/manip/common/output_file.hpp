#pragma once
// Output files a lab cannot lose. Two ways to write, one rule: no tool
// destroys or truncates an existing file unless told to (`force`), no tool
// leaves a truncated or empty output behind when it fails, and an output in
// use by another running instance is refused (flock), so two processes can
// never interleave or overwrite each other's session.
//
//   LockedOutput  a file written in place over a long time (manip_rt's session
//                 log): created with O_EXCL (no check-then-open race), or with
//                 `force` opened without truncation, locked, then truncated.
//                 discard() removes it when the run fails before any good data
//                 was written; commit() keeps it (a session cut short by a
//                 fault or a full disk keeps everything written before).
//   AtomicOutput  a file produced in one go (reports, JSON, CSV, simulated
//                 logs): written to a hidden temporary in the same directory
//                 and renamed over the target on commit(); never committed =
//                 the target is untouched and the temporary removed.
// Both throw manip::OutputError (exit code 6) naming the path and the reason.
#include <cstdio>
#include <string>

namespace manip {

class LockedOutput {
 public:
  LockedOutput() = default;
  // Throws OutputError: exists without force, in use by another process
  // (lock held), cannot be created.
  static LockedOutput open(const std::string& path, bool force);
  LockedOutput(LockedOutput&& o) noexcept;
  LockedOutput& operator=(LockedOutput&& o) noexcept;
  LockedOutput(const LockedOutput&) = delete;
  LockedOutput& operator=(const LockedOutput&) = delete;
  ~LockedOutput();  // closes; keeps the file unless discard() was called

  [[nodiscard]] bool is_open() const { return f_ != nullptr; }
  [[nodiscard]] std::FILE* stream() const { return f_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  // Gives the stream to a writer that will fclose it (the lock lives as long
  // as the open file description, i.e. until that fclose).
  std::FILE* release();
  // Removes the file this object created or truncated and closes it.
  void discard() noexcept;

 private:
  std::FILE* f_{nullptr};
  std::string path_;
};

class AtomicOutput {
 public:
  // Throws OutputError if the target exists and !force, or the directory is
  // not writable. The check is repeated atomically at commit().
  AtomicOutput(const std::string& path, bool force);
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;
  ~AtomicOutput();  // not committed: removes the temporary

  [[nodiscard]] std::FILE* stream() const { return f_; }
  [[nodiscard]] const std::string& temp_path() const { return tmp_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  // Flushes, fsyncs, closes and renames onto the target (without force: only
  // if the target still does not exist). Throws OutputError on any failure
  // (disk full included); the target is then untouched.
  void commit();

 private:
  std::FILE* f_{nullptr};
  std::string path_, tmp_;
  bool force_{false};
  bool committed_{false};
};

// Writes a whole text in one go through AtomicOutput.
void write_file_atomically(const std::string& path, const std::string& text, bool force);

}  // namespace manip
