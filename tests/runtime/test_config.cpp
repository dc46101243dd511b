// Configuration: the shipped file, strictness, and error messages naming file, line, key and reason.
#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>

#include "manip/runtime/config.hpp"
#include "manip/runtime/session.hpp"
#include "manip/schema/session_description.hpp"
#include "../control/test_support.hpp"

using namespace manip::control;
using namespace manip::runtime;

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
  } catch (const manip::ConfigError& e) {
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

TEST_CASE("the shipped config/rt.yaml is valid and equals the built-in defaults, every field", "[config]") {
  const RtConfig c = test_support::shipped_config();
  const RtConfig d;
  INFO("first differing key: " << first_difference(c, d));
  CHECK(first_difference(c, d).empty());
  // The values the paper fixes (§4.2, §5.1, §5.2), independently of both.
  CHECK(c.session.sample_rate_hz == 4000.0);
  CHECK(c.drive_decimation() == 2);
  CHECK(c.session.m_adm_kg == manip::Vec2(5.0, 5.0));
  CHECK(c.session.d_adm_nspm == manip::Vec2(15.0, 15.0));
  CHECK(c.session.perturbation.duration_s == 0.15);
  CHECK(c.session.perturbation.amplitude_n == 15.0);
  CHECK(c.session.perturbation.trigger_x2_shoulder_m == 0.40);
  CHECK(c.protocol.movements == 100);
  CHECK(c.perturbed_count() == 24);
  // rt.yaml's stable voluntary gains (its comment: 300/30 is unstable on M_adm = 5 kg)
  CHECK(c.sim.human.k_voluntary_npm == manip::Mat2::Identity() * 100.0);
  CHECK(c.sim.human.d_voluntary_nspm == manip::Mat2::Identity() * 20.0);
  CHECK(c.effective_yaml == shipped_text());  // no overrides: the file verbatim
  CHECK(d.session.invalid_reason() == std::nullopt);
}

TEST_CASE("the defaults comparison sees a change in any field", "[config]") {
  // One override per section and per session field: first_difference must
  // name it, so the defaults test above cannot pass by comparing too little.
  const std::vector<std::pair<std::string, std::string>> changes = {
      {"participant.session_id", "\"other\""},
      {"participant.body_mass_kg", "70"},
      {"participant.segment_length_m", "[0.30, 0.34]"},
      {"participant.segment_inertia_kgm2", "[0.0141, 0.02]"},
      {"frames.workspace_origin_in_shoulder_m", "[0.001, 0.425]"},
      {"frames.workspace_to_shoulder_rot_rad", "0.1"},
      {"loop.sample_rate_hz", "2000.0"},
      {"loop.priority", "70"},
      {"loop.max_commands_per_cycle", "3"},
      {"admittance.d_adm_nspm", "[15.0, 16.0]"},
      {"handle.mass_kg", "[0.25, 0.3]"},
      {"pd.ff_sensor_force_gain", "0.5"},
      {"safety.shutdown_cycles", "41"},
      {"perturbation.trigger_x2_shoulder_m", "0.41"},
      {"perturbation.repeats_per_angle", "2"},
      {"protocol.max_requeues", "2"},
      {"logger.flush_interval_s", "0.25"},
      {"bus.health_rate_hz", "2.0"},
      {"bus.state_rate_hz", "125.0"},
      {"sim.substeps", "2"},
      {"sim.human.motor_noise_tau_s", "0.06"},
      {"sim.participant.lateral_bow_std_m", "0.004"},
  };
  const RtConfig d;
  for (const auto& [key, value] : changes) {
    const RtConfig c = test_support::shipped_config({{key, value}});
    INFO(key << " = " << value);
    const std::string diff = first_difference(c, d);
    CHECK_FALSE(diff.empty());
    CHECK(diff.find(key.substr(0, key.find('.'))) != std::string::npos);
  }
}

TEST_CASE("one session description: a value changed in rt.yaml reaches the session message", "[config][session]") {
  const RtConfig c = test_support::shipped_config({{"handle.mass_kg", "[0.4, 0.45]"},
                                                    {"participant.segment_mass_kg", "[2.0, 1.6]"},
                                                    {"admittance.m_adm_kg", "[6.0, 7.0]"}});
  const manip::session_t m = manip::schema::to_message(session_of_run(c, "manip_rt/test", 123));
  CHECK(m.m_handle_kg[0] == 0.4);
  CHECK(m.m_handle_kg[1] == 0.45);
  CHECK(m.segment_mass_kg[0] == 2.0);
  CHECK(m.segment_mass_kg[1] == 1.6);
  CHECK(m.m_adm_kg[0] == 6.0);
  CHECK(m.m_adm_kg[1] == 7.0);
  CHECK(m.source == "manip_rt/test");
  CHECK(m.utime_start == 123);
  CHECK(m.config_yaml == c.effective_yaml);
  CHECK(m.participant_id == "sim-001");
  // and the controller's admittance is the same one (eq. 20)
  const manip::schema::SessionDescription back = manip::schema::from_message(m);
  CHECK(back.m_adm_kg == c.session.m_adm_kg);
  CHECK(back.m_handle_kg == c.session.m_handle_kg);
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
  SECTION("duplicate key") {
    CHECK(error_of(replace(base, "  movements: 100", "  movements: 100\n  movements: 10")).find("protocol.movements: duplicate key") !=
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
