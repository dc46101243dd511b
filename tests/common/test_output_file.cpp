// Output files: no clobbering without force, nothing left behind on failure,
// a file in use by another writer refused.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"

namespace fs = std::filesystem;

namespace {
fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("manip_output_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}
std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}
std::size_t entries(const fs::path& d) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(d)) ++n;
  return n;
}
std::string output_error(const std::function<void()>& f) {
  try {
    f();
  } catch (const manip::OutputError& e) {
    CHECK(e.exit_code() == manip::exit_code::kOutput);
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("AtomicOutput: written on commit only, never clobbers without force") {
  const fs::path d = temp_dir("atomic");
  const std::string p = (d / "r.json").string();
  {
    manip::AtomicOutput o(p, false);
    std::fputs("partial", o.stream());
    CHECK(!fs::exists(p));  // nothing visible before commit
  }  // not committed: the temporary is gone, no target
  CHECK(!fs::exists(p));
  CHECK(entries(d) == 0);

  manip::write_file_atomically(p, "first\n", false);
  CHECK(slurp(p) == "first\n");
  CHECK(output_error([&] { manip::write_file_atomically(p, "second\n", false); }) ==
        p + ": exists (pass --force to overwrite it)");
  CHECK(slurp(p) == "first\n");
  manip::write_file_atomically(p, "second\n", true);
  CHECK(slurp(p) == "second\n");
  CHECK(entries(d) == 1);

  // The target appears between the check and the commit: not overwritten.
  const std::string q = (d / "late.json").string();
  {
    manip::AtomicOutput o(q, false);
    std::fputs("mine", o.stream());
    std::ofstream(q) << "theirs";
    CHECK(output_error([&] { o.commit(); }).find("created by someone else meanwhile") != std::string::npos);
  }
  CHECK(slurp(q) == "theirs");
  CHECK(entries(d) == 2);
  fs::remove_all(d);
}

TEST_CASE("LockedOutput: exclusive create, force keeps a file in use, discard removes") {
  const fs::path d = temp_dir("locked");
  const std::string p = (d / "s.lcm").string();
  {
    manip::LockedOutput a = manip::LockedOutput::open(p, false);
    std::fputs("session A", a.stream());
    std::fflush(a.stream());
    CHECK(output_error([&] { (void)manip::LockedOutput::open(p, false); }) ==
          p + ": exists (pass --force to overwrite it)");
    // A second instance with --force on the same path while A is running:
    // refused, and A's data is intact (no truncation before the lock).
    CHECK(output_error([&] { (void)manip::LockedOutput::open(p, true); }).find("in use by another running process") !=
          std::string::npos);
    CHECK(slurp(p) == "session A");
  }
  // A finished: --force may now overwrite it.
  {
    manip::LockedOutput b = manip::LockedOutput::open(p, true);
    CHECK(slurp(p).empty());
    std::fputs("session B", b.stream());
  }
  CHECK(slurp(p) == "session B");
  {
    const std::string q = (d / "failed.lcm").string();
    manip::LockedOutput c = manip::LockedOutput::open(q, false);
    std::fputs("header", c.stream());
    c.discard();  // start-up failed: no stub left to block the rerun
    CHECK(!fs::exists(q));
  }
  fs::remove_all(d);
}
