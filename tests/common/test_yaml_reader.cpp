// The strict YAML reader: every error names file, line, key and reason;
// unknown and duplicate keys are refused.
#include <catch2/catch.hpp>

#include <string>

#include "manip/common/yaml_reader.hpp"

using manip::ConfigError;
namespace yaml = manip::yaml;

namespace {
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const ConfigError& e) {
    CHECK(e.exit_code() == manip::exit_code::kConfig);
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("yaml reader: values, ranges and unknown keys") {
  const std::string text = "a:\n  x: 1.5\n  n: 3\n  v: [1, 2]\n  m: [[2, 0], [0, 3]]\n  s: hello\nb: true\n";
  const YAML::Node root = yaml::parse(text, "t.yaml");
  yaml::Section top("t.yaml", root, "");
  yaml::Section a = top.sub("a");
  CHECK(a.positive("x") == 1.5);
  CHECK(a.integer("n", 0, 10) == 3);
  CHECK(a.vec2_positive("v") == manip::Vec2(1, 2));
  CHECK(a.mat2_spd("m")(1, 1) == 3.0);
  CHECK(a.choice("s", {"hello", "bye"}) == "hello");
  a.finish();
  CHECK(top.boolean("b"));
  top.finish();

  yaml::Section top2("t.yaml", yaml::parse(text, "t.yaml"), "");
  yaml::Section a2 = top2.sub("a");
  CHECK(error_of([&] { a2.integer("n", 5, 10); }) == "t.yaml:3: a.n: must be in [5, 10] (got 3)");
  CHECK(error_of([&] { a2.finish(); }).rfind("t.yaml:", 0) == 0);
  CHECK(error_of([&] { a2.finish(); }).find("unknown key") != std::string::npos);
  CHECK(error_of([&] { top2.positive("missing"); }) == "t.yaml:1: missing: missing (required key)");
}

TEST_CASE("yaml reader: duplicate keys and syntax errors name the line") {
  CHECK(error_of([] { yaml::parse("a: 1\nb:\n  c: 2\n  c: 3\n", "d.yaml"); }) ==
        "d.yaml:4: b.c: duplicate key (given twice in one mapping)");
  CHECK(error_of([] { yaml::parse("a: 1\na: 2\n", "d.yaml"); }) == "d.yaml:2: a: duplicate key (given twice in one mapping)");
  const std::string syntax = error_of([] { yaml::parse("a: [1, 2\nb: 3\n", "s.yaml"); });
  CHECK(syntax.rfind("s.yaml:", 0) == 0);
  CHECK(syntax.find("YAML syntax error") != std::string::npos);
  CHECK(error_of([] { yaml::load_file("/nonexistent/x.yaml"); }) == "/nonexistent/x.yaml: cannot read the file");
}

TEST_CASE("yaml reader: a key that is not a plain name is refused with file, line and key") {
  // Complex keys ("? node") are valid YAML: a sequence, a mapping, or nothing (null).
  for (const std::string text : {"a: 1\n? [x, y]\n: 2\n", "a: 1\n? {x: 1}\n: 2\n", "a: 1\n?\n: 2\n"}) {
    INFO(text);
    yaml::Section top("k.yaml", yaml::parse(text, "k.yaml"), "");
    CHECK(top.number("a", [](double) { return true; }, "") == 1.0);
    const std::string e = error_of([&] { top.finish(); });
    CHECK(e.rfind("k.yaml:", 0) == 0);
    CHECK(e.find(": a key must be a plain name, not a sequence, mapping or null") != std::string::npos);
  }
}

TEST_CASE("yaml reader: non-finite numbers are refused") {
  yaml::Section s("n.yaml", yaml::parse("x: .nan\ny: .inf\n", "n.yaml"), "");
  CHECK(error_of([&] { s.any_number("x"); }) == "n.yaml:1: x: expected a finite number, got '.nan'");
  CHECK(error_of([&] { s.any_number("y"); }) == "n.yaml:2: y: expected a finite number, got '.inf'");
}
