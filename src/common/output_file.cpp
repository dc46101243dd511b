#include "manip/common/output_file.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "manip/common/errors.hpp"

namespace manip {
namespace {

std::string why(int err) { return std::strerror(err); }

}  // namespace

LockedOutput LockedOutput::open(const std::string& path, bool force) {
  // O_EXCL makes "does it exist?" and "create it" one step: two instances
  // started on the same path cannot both pass the check.
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0 && errno == EEXIST) {
    if (!force) throw OutputError(path + ": exists (pass --force to overwrite it)");
    // No O_TRUNC: a file another instance is writing must survive our attempt.
    fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  }
  if (fd < 0) throw OutputError(path + ": cannot create (" + why(errno) + ")");
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int e = errno;
    ::close(fd);
    if (e == EWOULDBLOCK) throw OutputError(path + ": in use by another running process (locked); not touched");
    throw OutputError(path + ": cannot lock (" + why(e) + ")");
  }
  if (::ftruncate(fd, 0) != 0) {
    const int e = errno;
    ::close(fd);
    throw OutputError(path + ": cannot truncate (" + why(e) + ")");
  }
  LockedOutput out;
  out.f_ = ::fdopen(fd, "wb");
  if (!out.f_) {
    const int e = errno;
    ::close(fd);
    throw OutputError(path + ": cannot open a stream (" + why(e) + ")");
  }
  out.path_ = path;
  return out;
}

LockedOutput::LockedOutput(LockedOutput&& o) noexcept : f_(o.f_), path_(std::move(o.path_)) { o.f_ = nullptr; }
LockedOutput& LockedOutput::operator=(LockedOutput&& o) noexcept {
  if (this != &o) {
    if (f_) std::fclose(f_);
    f_ = o.f_;
    path_ = std::move(o.path_);
    o.f_ = nullptr;
  }
  return *this;
}
LockedOutput::~LockedOutput() {
  if (f_) std::fclose(f_);
}

std::FILE* LockedOutput::release() {
  std::FILE* f = f_;
  f_ = nullptr;
  return f;
}

void LockedOutput::discard() noexcept {
  if (!f_) return;
  // Unlink while the lock is held, so no other instance can have opened it.
  ::unlink(path_.c_str());
  std::fclose(f_);
  f_ = nullptr;
}

AtomicOutput::AtomicOutput(const std::string& path, bool force) : path_(path), force_(force) {
  struct stat st {};
  if (!force && ::lstat(path.c_str(), &st) == 0) throw OutputError(path + ": exists (pass --force to overwrite it)");
  const std::filesystem::path p(path);
  const std::string dir = p.has_parent_path() ? p.parent_path().string() : std::string(".");
  std::string tmpl = dir + "/." + p.filename().string() + ".partial-XXXXXX";
  const int fd = ::mkstemp(tmpl.data());
  if (fd < 0) throw OutputError(path + ": cannot create a temporary file in " + dir + " (" + why(errno) + ")");
  tmp_ = tmpl;
  f_ = ::fdopen(fd, "wb");
  if (!f_) {
    const int e = errno;
    ::close(fd);
    ::unlink(tmp_.c_str());
    throw OutputError(path + ": cannot open a stream (" + why(e) + ")");
  }
}

AtomicOutput::~AtomicOutput() {
  if (f_) std::fclose(f_);
  if (!committed_ && !tmp_.empty()) ::unlink(tmp_.c_str());
}

void AtomicOutput::commit() {
  if (!f_) throw OutputError(path_ + ": already committed or closed");
  bool ok = std::fflush(f_) == 0 && !std::ferror(f_);
  int err = ok ? 0 : errno;
  if (ok && ::fsync(::fileno(f_)) != 0) {
    ok = false;
    err = errno;
  }
  if (std::fclose(f_) != 0 && ok) {
    ok = false;
    err = errno;
  }
  f_ = nullptr;
  if (!ok) throw OutputError(path_ + ": write failed (" + why(err) + "); the target was not touched");
  if (force_) {
    if (::rename(tmp_.c_str(), path_.c_str()) != 0)
      throw OutputError(path_ + ": cannot rename the finished file into place (" + why(errno) + ")");
  } else {
    // link() fails with EEXIST if the target appeared meanwhile: never clobber.
    if (::link(tmp_.c_str(), path_.c_str()) != 0) {
      const int e = errno;
      if (e == EEXIST) throw OutputError(path_ + ": was created by someone else meanwhile; not overwritten");
      throw OutputError(path_ + ": cannot move the finished file into place (" + why(e) + ")");
    }
    ::unlink(tmp_.c_str());
  }
  committed_ = true;
}

void write_file_atomically(const std::string& path, const std::string& text, bool force) {
  AtomicOutput out(path, force);
  if (std::fwrite(text.data(), 1, text.size(), out.stream()) != text.size())
    throw OutputError(path + ": write failed (" + std::strerror(errno) + ")");
  out.commit();
}

}  // namespace manip
