#pragma once
// Every setting of the estimator in one place, with its YAML form
// (config/estimator.yaml documents the keys) and its JSON echo in reports.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/pem.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

// Ranges shared by --config and the command line (an option outside them is
// refused before any log is read).
inline constexpr double kMaxCutoffHz = 100.0;  // high-pass of the jerk: the paper uses ~1 Hz; < any log's Nyquist
inline constexpr int kMinSgWindow = 7;         // > sg_order (5) + 1: a window of 3 cannot fit an order-5 polynomial
inline constexpr int kMaxSgWindow = 100001;

struct EstimatorSettings {
  PipelineSettings pipeline{};
  bool cutoff_auto{false};
  double cutoff_auto_threshold_db{3.0};
  int psd_nfft{65536};
  LsOptions ls{};
  OeSettings oe{};
  PemSettings pem{};
  PositionSource position{PositionSource::automatic};  // the handle position every method sees (trial_data.hpp)
  std::vector<std::string> methods{default_method()};  // names in the method registry (methods/registry.hpp)
  bool keep_windows{false};  // keep variational windows for --export-signals / --plots
};

// Loads settings from YAML on top of `base` through the strict reader
// (common/yaml_reader.hpp): every key optional; unknown keys, keys given
// twice, wrong types and values out of range throw manip::ConfigError
// ("<file>:<line>: <key>: <reason>", exit code 3). `methods` is checked
// against the registry ("all" = every registered method).
EstimatorSettings load_estimator_settings(const std::string& path, EstimatorSettings base = {});

nlohmann::json settings_to_json(const EstimatorSettings& s);

}  // namespace manip::estimation
