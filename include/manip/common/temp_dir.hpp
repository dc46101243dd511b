#pragma once
// A private temporary directory removed with everything in it when the
// object goes out of scope (the apps' intermediate files for --plots/--report).
#include <filesystem>
#include <random>
#include <string>
#include <system_error>

#include "manip/common/errors.hpp"

namespace manip {

class ScopedTempDir {
 public:
  // $TMPDIR/<prefix>_<random>; OutputError (exit 6) when it cannot be created.
  explicit ScopedTempDir(const std::string& prefix) {
    std::error_code e;
    std::mt19937_64 rng(std::random_device{}());
    path_ = std::filesystem::temp_directory_path(e) / (prefix + "_" + std::to_string(rng() % 1000000000));
    std::filesystem::create_directories(path_, e);
    if (e) throw OutputError(path_.string() + ": cannot create a temporary directory (" + e.message() + ")");
  }
  ~ScopedTempDir() {
    std::error_code e;
    std::filesystem::remove_all(path_, e);
  }
  ScopedTempDir(const ScopedTempDir&) = delete;
  ScopedTempDir& operator=(const ScopedTempDir&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace manip
