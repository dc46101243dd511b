#pragma once
// The one error style for set-up (reading configs, opening logs and outputs,
// starting backends): typed exceptions that carry the exit code of
// common/exit_codes.hpp and a one-line message naming what and where
// ("config/rt.yaml:42: pd.kp_npm: must be > 0 (got -3)"). Apps catch
// manip::Error once in main and return its code. The real-time path never
// throws: it reports through status words and fault bits.
#include <stdexcept>
#include <string>

#include "manip/common/exit_codes.hpp"

namespace manip {

class Error : public std::runtime_error {
 public:
  Error(int exit_code, const std::string& what) : std::runtime_error(what), exit_code_(exit_code) {}
  [[nodiscard]] int exit_code() const noexcept { return exit_code_; }

 private:
  int exit_code_;
};

struct UsageError : Error {
  explicit UsageError(const std::string& what) : Error(exit_code::kUsage, what) {}
};
struct ConfigError : Error {
  explicit ConfigError(const std::string& what) : Error(exit_code::kConfig, what) {}
};
struct InputError : Error {
  explicit InputError(const std::string& what) : Error(exit_code::kInput, what) {}
};
struct OutputError : Error {
  explicit OutputError(const std::string& what) : Error(exit_code::kOutput, what) {}
};

}  // namespace manip
