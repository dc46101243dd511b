// Estimator settings: config/estimator.yaml states the built-in defaults
// (whole struct compared), and the loader is the strict one of
// common/yaml_reader.hpp (unknown and duplicate keys refused with file:line).
#include <catch2/catch.hpp>

#include <fstream>

#include "fixtures.hpp"
#include "manip/common/errors.hpp"
#include "manip/estimation/settings.hpp"

using namespace manip;
using namespace manip::estimation;

namespace {
std::string write(const std::string& name, const std::string& text) {
  static const auto dir = testutil::temp_dir("estimator_settings");
  std::ofstream(dir + "/" + name) << text;
  return dir + "/" + name;
}
std::string config_error(const std::string& path) {
  try {
    (void)load_estimator_settings(path);
  } catch (const manip::ConfigError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("settings: config/estimator.yaml equals the built-in defaults, every field") {
  const auto from_file = load_estimator_settings(std::string(MANIP_SOURCE_DIR) + "/config/estimator.yaml");
  // settings_to_json lists every field of EstimatorSettings that a file can set.
  CHECK(settings_to_json(from_file) == settings_to_json(EstimatorSettings{}));
  CHECK(from_file.cutoff_auto == EstimatorSettings{}.cutoff_auto);
  CHECK(from_file.keep_windows == EstimatorSettings{}.keep_windows);
}

TEST_CASE("settings: values are read, and t_est_s sets every method's window") {
  const auto s = load_estimator_settings(write("ok.yaml", "methods: [paper, oe]\nhp_cutoff_hz: auto\nt_est_s: 0.1\npem_se: fisher\n"));
  CHECK(s.methods == std::vector<std::string>{"paper", "oe"});
  CHECK(s.cutoff_auto);
  CHECK(s.pipeline.t_est_s == 0.1);
  CHECK(s.oe.t_est_s == 0.1);
  CHECK(s.pem.t_est_s == 0.1);
  CHECK(s.pem.se == PemSe::fisher);
  CHECK(s.position == PositionSource::automatic);
  CHECK(load_estimator_settings(write("pos.yaml", "position_source: reference\n")).position == PositionSource::reference);
  CHECK(load_estimator_settings(write("pos_enc.yaml", "position_source: encoder\n")).position == PositionSource::encoder);
  CHECK(load_estimator_settings(write("pos_auto.yaml", "position_source: auto\n")).position == PositionSource::automatic);
  CHECK(load_estimator_settings(write("pos_trk.yaml", "position_source: tracked\n")).position == PositionSource::tracked);
  const auto bad_pos = write("bad_pos.yaml", "position_source: stage\n");
  CHECK(config_error(bad_pos).find(bad_pos + ":1: position_source") == 0);
  CHECK(load_estimator_settings(write("all.yaml", "methods: [all]\n")).methods == all_methods());
}

TEST_CASE("settings: unknown keys, duplicate keys, bad values and unknown methods are refused with file:line") {
  const auto unknown = write("unknown.yaml", "hp_order: 5\nhp_ordr: 4\n");
  CHECK(config_error(unknown).find(unknown + ":2: hp_ordr: unknown key") == 0);
  const auto dup = write("dup.yaml", "sg_order: 5\nsg_order: 3\n");
  CHECK(config_error(dup).find(dup + ":2") == 0);
  const auto range = write("range.yaml", "sg_order: 11\n");
  CHECK(config_error(range).find(range + ":1: sg_order: must be in [1, 10]") == 0);
  const auto even = write("even.yaml", "sg_window: 224\n");
  CHECK(config_error(even).find("sg_window: must be odd") != std::string::npos);
  const auto method = write("method.yaml", "methods: [paper, nope]\n");
  CHECK(config_error(method).find("unknown method 'nope'") != std::string::npos);
  CHECK(config_error(write("missing_dir/none.yaml", "")).find("none.yaml") != std::string::npos);
}
