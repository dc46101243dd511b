// Configuration: the shipped file, strictness, and error messages naming file, line, key and reason.
#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>

#include "manip/control/config.hpp"
#include "test_support.hpp"

using namespace manip::control;

namespace {
std::string shipped_text() {
  std::ifstream in(test_support::shipped_config_path());
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}
std::string error_of(const std::string& text) {
  try {
    parse_rt_config(text, "cfg.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}
std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto p = s.find(from);
  REQUIRE(p != std::string::npos);
  s.replace(p, from.size(), to);
  return s;
}
}  // namespace

TEST_CASE("the shipped config/rt.yaml is valid and equals the built-in defaults", "[config]") {
  const RtConfig c = test_support::shipped_config();
  const RtConfig d;
  CHECK(c.loop.sample_rate_hz == d.loop.sample_rate_hz);
  CHECK(c.loop.drive_decimation() == 2);
  CHECK(c.admittance.m_adm_kg == d.admittance.m_adm_kg);
  CHECK(c.admittance.d_adm_nspm == d.admittance.d_adm_nspm);
  CHECK(c.handle_mass_kg == d.handle_mass_kg);
  CHECK(c.pd.kp_npm == d.pd.kp_npm);
  CHECK(c.pd.kd_nspm == d.pd.kd_nspm);
  CHECK(c.pd.ff_mass_kg == d.pd.ff_mass_kg);
  CHECK(c.frames.origin_in_shoulder_m == d.frames.origin_in_shoulder_m);
  CHECK(c.protocol.movements == 100);
  CHECK(c.perturbed_count() == 24);
  CHECK(c.protocol.seed == d.protocol.seed);
  CHECK(c.protocol.goal_hold_s == d.protocol.goal_hold_s);
  CHECK(c.safety.max_motor_force_n == d.safety.max_motor_force_n);
  CHECK(c.safety.workspace_limit_m == d.safety.workspace_limit_m);
  CHECK(c.sim.stage_mass_kg == d.sim.stage_mass_kg);
  CHECK(c.sim.human.k_npm == d.sim.human.k_npm);
  CHECK(c.sim.human.m_load_kg == d.sim.human.m_load_kg);
  CHECK(c.effective_yaml == shipped_text());  // no overrides: the file verbatim
}

TEST_CASE("config errors name the file, the line, the key and the reason", "[config]") {
  const std::string base = shipped_text();
  SECTION("unknown key") {
    const std::string e = error_of(replace(base, "  mass_kg: [0.25, 0.25]", "  mass_kg: [0.25, 0.25]\n  mass_kgg: 1"));
    CHECK(e.find("cfg.yaml:") == 0);
    CHECK(e.find("handle.mass_kgg: unknown key") != std::string::npos);
    // "cfg.yaml:<line>: " (no <regex>: GCC 12 + sanitizers warn inside it)
    const auto colon = e.find(':', 9);
    REQUIRE(colon != std::string::npos);
    CHECK(colon > 9);
    CHECK(e.substr(9, colon - 9).find_first_not_of("0123456789") == std::string::npos);
    CHECK(e.compare(colon, 2, ": ") == 0);
  }
  SECTION("unknown top-level section") {
    CHECK(error_of(base + "\nextra:\n  a: 1\n").find("extra: unknown key") != std::string::npos);
  }
  SECTION("missing key") {
    const std::string e = error_of(replace(base, "  d_adm_nspm: [15.0, 15.0]", ""));
    CHECK(e.find("admittance.d_adm_nspm: missing") != std::string::npos);
  }
  SECTION("wrong type") {
    const std::string e = error_of(replace(base, "movements: 100", "movements: lots"));
    CHECK(e.find("protocol.movements: expected an integer, got 'lots'") != std::string::npos);
  }
  SECTION("out of range, with the line") {
    const std::string text = replace(base, "kp_npm: [3.0e5, 1.0e5]", "kp_npm: [3.0e5, -1.0]");
    int line = 0, i = 0;
    std::istringstream is(text);
    for (std::string l; std::getline(is, l);) {
      ++i;
      if (l.find("kp_npm: [3.0e5, -1.0]") != std::string::npos) line = i;
    }
    const std::string e = error_of(text);
    CHECK(e.find("cfg.yaml:" + std::to_string(line) + ": pd.kp_npm: every element must be > 0") == 0);
  }
  SECTION("wrong list length") {
    CHECK(error_of(replace(base, "m_adm_kg: [5.0, 5.0]", "m_adm_kg: [5.0]")).find("admittance.m_adm_kg: expected 2 numbers, got 1") !=
          std::string::npos);
  }
  SECTION("drive rate must divide the sample rate") {
    CHECK(error_of(replace(base, "drive_rate_hz: 2000.0", "drive_rate_hz: 1500.0")).find("loop.drive_rate_hz: must divide") !=
          std::string::npos);
  }
  SECTION("perturbation beyond its safety limit") {
    CHECK(error_of(replace(base, "amplitude_n: 15.0", "amplitude_n: 45.0")).find("perturbation.amplitude_n: exceeds safety.max_pert_amplitude_n") !=
          std::string::npos);
  }
  SECTION("targets outside the walls") {
    CHECK(error_of(replace(base, "goal_shoulder_m: [0.0, 0.55]", "goal_shoulder_m: [0.0, 0.60]")).find("protocol.goal_shoulder_m: target") !=
          std::string::npos);
  }
  SECTION("more perturbed trials than movements") {
    CHECK(error_of(replace(base, "movements: 100", "movements: 10")).find("protocol.movements: fewer movements (10) than perturbed trials (24)") !=
          std::string::npos);
  }
  SECTION("bad choice") {
    CHECK(error_of(replace(base, "safe_law: damping", "safe_law: brake")).find("safety.safe_law: must be one of zero_force, damping") !=
          std::string::npos);
  }
  SECTION("YAML syntax") {
    CHECK(error_of("loop: [1, 2\n").find("cfg.yaml:") == 0);
  }
  SECTION("unreadable file") {
    CHECK_THROWS_WITH(load_rt_config("/nonexistent/rt.yaml"), Catch::Contains("/nonexistent/rt.yaml: cannot read"));
  }
}

TEST_CASE("config overrides: applied, validated and recorded in the effective text", "[config]") {
  const RtConfig c = test_support::shipped_config({{"protocol.seed", "7"}, {"bus.lcm_url", "\"memq://\""}});
  CHECK(c.protocol.seed == 7u);
  CHECK(c.bus.lcm_url == "memq://");
  CHECK(c.effective_yaml.find("command-line overrides protocol.seed=7") != std::string::npos);
  const RtConfig again = parse_rt_config(c.effective_yaml, "effective");
  CHECK(again.protocol.seed == 7u);
  CHECK_THROWS_WITH(test_support::shipped_config({{"protocol.movements", "-1"}}),
                    Catch::Contains("protocol.movements: must be in [1, 100000]"));
  CHECK_THROWS_WITH(test_support::shipped_config({{"nosuch.key", "1"}}), Catch::Contains("no section nosuch"));
}
