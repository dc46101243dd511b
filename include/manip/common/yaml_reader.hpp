#pragma once
// The one strict YAML reader of manip (config/rt.yaml, config/arm_model.yaml,
// config/estimator.yaml, the CAN bus file). Every error is one line,
//   "<file>:<line>: <key.path>: <reason>",
// thrown as manip::ConfigError (exit code 3). Strict means: a key that is never
// asked for is an error (a misspelt key must not silently leave a default in
// force), a key given twice in one mapping is an error (yaml-cpp keeps both and
// returns the first), and numbers must be finite.
#include <cstdint>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "manip/common/errors.hpp"
#include "manip/common/types.hpp"

namespace manip::yaml {

// Parses text (syntax errors and duplicate keys anywhere become ConfigError
// naming `file` and the line).
YAML::Node parse(const std::string& text, const std::string& file);
// Reads and parses a file (ConfigError if it cannot be read).
YAML::Node load_file(const std::string& path);
// Reads a whole text file; ConfigError naming it if it cannot be read.
std::string read_text_file(const std::string& path);

// The scalar text of a node for messages (flow style for collections).
std::string scalar_text(const YAML::Node& n);

// Strict reader of one mapping: every access marks a key as known; finish()
// rejects the keys that were never asked for.
class Section {
 public:
  Section(const std::string& file, const YAML::Node& node, std::string path);

  [[noreturn]] void fail_node(const YAML::Node& n, const std::string& key, const std::string& why) const;
  [[noreturn]] void fail(const std::string& key, const std::string& why) const;
  [[nodiscard]] std::string full(const std::string& key) const;
  [[nodiscard]] const std::string& file() const { return file_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] const YAML::Node& node() const { return node_; }

  // Required unless `required` is false (then an undefined/null node).
  YAML::Node get(const std::string& key, bool required = true);
  bool has(const std::string& key);
  Section sub(const std::string& key);

  double number(const std::string& key, const std::function<bool(double)>& ok, const char* rule);
  double any_number(const std::string& key);
  double positive(const std::string& key);
  double nonneg(const std::string& key);
  long long integer(const std::string& key, long long lo, long long hi);
  std::uint64_t unsigned64(const std::string& key);
  bool boolean(const std::string& key);
  std::string string(const std::string& key, bool allow_empty = false);
  std::string choice(const std::string& key, const std::vector<std::string>& allowed);
  // n_expected 0: any length >= 1.
  std::vector<double> numbers(const std::string& key, std::size_t n_expected);
  Vec2 vec2(const std::string& key, const std::function<bool(double)>& ok = nullptr, const char* rule = "");
  Vec2 vec2_positive(const std::string& key);
  Vec2 vec2_nonneg(const std::string& key);
  Mat2 mat2(const std::string& key);
  Mat2 mat2_spd(const std::string& key);

  // Rejects every key of this mapping that was never asked for.
  void finish() const;

 private:
  std::string file_;
  YAML::Node node_;
  std::string path_;
  std::set<std::string> known_;
};

}  // namespace manip::yaml
