#include "manip/common/yaml_reader.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

namespace manip::yaml {
namespace {

std::string where(const std::string& file, const YAML::Mark& m) {
  std::string s = file;
  if (m.line >= 0) s += ":" + std::to_string(m.line + 1);
  return s;
}

// yaml-cpp keeps both entries of a repeated key and node[key] returns the
// first, so a later correction in a config would be silently ignored.
void reject_duplicates(const YAML::Node& n, const std::string& file, const std::string& path) {
  if (n.IsMap()) {
    std::set<std::string> seen;
    for (const auto& kv : n) {
      const std::string k = kv.first.IsScalar() ? kv.first.Scalar() : scalar_text(kv.first);
      const std::string full = path.empty() ? k : path + "." + k;
      if (!seen.insert(k).second)
        throw ConfigError(where(file, kv.first.Mark()) + ": " + full + ": duplicate key (given twice in one mapping)");
      reject_duplicates(kv.second, file, full);
    }
  } else if (n.IsSequence()) {
    for (std::size_t i = 0; i < n.size(); ++i) reject_duplicates(n[i], file, path + "[" + std::to_string(i) + "]");
  }
}

}  // namespace

std::string scalar_text(const YAML::Node& n) {
  if (n.IsScalar()) return n.Scalar();
  std::ostringstream os;
  os << n;
  std::string s = os.str();
  for (auto& c : s)
    if (c == '\n') c = ' ';
  return s;
}

YAML::Node parse(const std::string& text, const std::string& file) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(where(file, e.mark) + ": YAML syntax error: " + e.msg);
  }
  reject_duplicates(root, file, "");
  return root;
}

std::string read_text_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw ConfigError(path + ": cannot read the file");
  std::ostringstream ss;
  ss << f.rdbuf();
  if (f.bad()) throw ConfigError(path + ": read error");
  return ss.str();
}

YAML::Node load_file(const std::string& path) { return parse(read_text_file(path), path); }

Section::Section(const std::string& file, const YAML::Node& node, std::string path)
    : file_(file), node_(node), path_(std::move(path)) {
  if (!node_.IsMap()) fail_node(node_, path_.empty() ? "(top level)" : path_, "must be a mapping of keys");
}

void Section::fail_node(const YAML::Node& n, const std::string& key, const std::string& why) const {
  std::ostringstream os;
  os << file_;
  if (n.IsDefined() && n.Mark().line >= 0) os << ':' << n.Mark().line + 1;
  os << ": " << key << ": " << why;
  throw ConfigError(os.str());
}

void Section::fail(const std::string& key, const std::string& why) const {
  const YAML::Node n = node_[key];
  if (n.IsDefined()) fail_node(n, full(key), why);
  fail_node(node_, full(key), why);
}

std::string Section::full(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

YAML::Node Section::get(const std::string& key, bool required) {
  known_.insert(key);
  YAML::Node n = node_[key];
  if (!n.IsDefined() || n.IsNull()) {
    if (required) fail_node(node_, full(key), "missing (required key)");
    return YAML::Node();
  }
  return n;
}

bool Section::has(const std::string& key) {
  known_.insert(key);
  const YAML::Node n = node_[key];
  return n.IsDefined() && !n.IsNull();
}

Section Section::sub(const std::string& key) { return Section(file_, get(key), full(key)); }

double Section::number(const std::string& key, const std::function<bool(double)>& ok, const char* rule) {
  const YAML::Node n = get(key);
  double v{};
  if (!n.IsScalar() || !YAML::convert<double>::decode(n, v) || !std::isfinite(v))
    fail_node(n, full(key), "expected a finite number, got '" + scalar_text(n) + "'");
  if (ok && !ok(v)) fail_node(n, full(key), std::string(rule) + " (got " + scalar_text(n) + ")");
  return v;
}
double Section::any_number(const std::string& key) { return number(key, nullptr, ""); }
double Section::positive(const std::string& key) {
  return number(key, [](double v) { return v > 0; }, "must be > 0");
}
double Section::nonneg(const std::string& key) {
  return number(key, [](double v) { return v >= 0; }, "must be >= 0");
}

long long Section::integer(const std::string& key, long long lo, long long hi) {
  const YAML::Node n = get(key);
  long long v{};
  if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v))
    fail_node(n, full(key), "expected an integer, got '" + scalar_text(n) + "'");
  if (v < lo || v > hi)
    fail_node(n, full(key),
              "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] (got " + std::to_string(v) + ")");
  return v;
}

std::uint64_t Section::unsigned64(const std::string& key) {
  const YAML::Node n = get(key);
  unsigned long long v{};
  if (!n.IsScalar() || !YAML::convert<unsigned long long>::decode(n, v) || (!n.Scalar().empty() && n.Scalar()[0] == '-'))
    fail_node(n, full(key), "expected a non-negative integer, got '" + scalar_text(n) + "'");
  return v;
}

bool Section::boolean(const std::string& key) {
  const YAML::Node n = get(key);
  bool v{};
  if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v))
    fail_node(n, full(key), "expected true or false, got '" + scalar_text(n) + "'");
  return v;
}

std::string Section::string(const std::string& key, bool allow_empty) {
  const YAML::Node n = get(key);
  if (!n.IsScalar()) fail_node(n, full(key), "expected a string");
  if (!allow_empty && n.Scalar().empty()) fail_node(n, full(key), "must not be empty");
  return n.Scalar();
}

std::string Section::choice(const std::string& key, const std::vector<std::string>& allowed) {
  const std::string v = string(key);
  for (const auto& a : allowed)
    if (a == v) return v;
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  fail(key, "must be one of " + list + " (got '" + v + "')");
}

std::vector<double> Section::numbers(const std::string& key, std::size_t n_expected) {
  const YAML::Node n = get(key);
  if (!n.IsSequence()) fail_node(n, full(key), "expected a list of numbers");
  if (n_expected && n.size() != n_expected)
    fail_node(n, full(key), "expected " + std::to_string(n_expected) + " numbers, got " + std::to_string(n.size()));
  if (!n_expected && n.size() == 0) fail_node(n, full(key), "expected at least one number");
  std::vector<double> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    double v{};
    if (!n[i].IsScalar() || !YAML::convert<double>::decode(n[i], v) || !std::isfinite(v))
      fail_node(n[i], full(key),
                "element " + std::to_string(i) + " is not a finite number ('" + scalar_text(n[i]) + "')");
    out.push_back(v);
  }
  return out;
}

Vec2 Section::vec2(const std::string& key, const std::function<bool(double)>& ok, const char* rule) {
  const auto v = numbers(key, 2);
  if (ok)
    for (double x : v)
      if (!ok(x)) fail(key, std::string("every element ") + rule + " (got " + scalar_text(node_[key]) + ")");
  return Vec2(v[0], v[1]);
}
Vec2 Section::vec2_positive(const std::string& key) {
  return vec2(key, [](double v) { return v > 0; }, "must be > 0");
}
Vec2 Section::vec2_nonneg(const std::string& key) {
  return vec2(key, [](double v) { return v >= 0; }, "must be >= 0");
}

Mat2 Section::mat2(const std::string& key) {
  const YAML::Node n = get(key);
  if (!n.IsSequence() || n.size() != 2 || !n[0].IsSequence() || !n[1].IsSequence() || n[0].size() != 2 ||
      n[1].size() != 2)
    fail_node(n, full(key), "expected a 2x2 matrix [[a, b], [c, d]] (row-major, shoulder frame)");
  Mat2 m;
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 2; ++c) {
      double v{};
      if (!YAML::convert<double>::decode(n[r][c], v) || !std::isfinite(v))
        fail_node(n, full(key), "element (" + std::to_string(r) + "," + std::to_string(c) + ") is not a finite number");
      m(r, c) = v;
    }
  return m;
}

Mat2 Section::mat2_spd(const std::string& key) {
  const Mat2 m = mat2(key);
  const Mat2 s = 0.5 * (m + m.transpose());
  if (!(s(0, 0) > 0 && s.determinant() > 0)) fail(key, "must be positive definite");
  return m;
}

void Section::finish() const {
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    // YAML allows any node as a key ("? [a, b]: 1", "? : 1"); no manip key
    // is one, and as<std::string>() would throw yaml-cpp's own exception
    // past the ConfigError contract (found by fuzz_estimator_config).
    if (!it->first.IsScalar())
      fail_node(it->first, full(scalar_text(it->first)), "a key must be a plain name, not a sequence, mapping or null");
    const std::string k = it->first.Scalar();
    if (!known_.count(k)) {
      std::string list;
      for (const auto& a : known_) list += (list.empty() ? "" : ", ") + a;
      fail_node(it->first, full(k), "unknown key (known keys here: " + list + ")");
    }
  }
}

}  // namespace manip::yaml
