#pragma once
// Presenting a Report: the Table-1 text summary, JSON (layout in
// docs/estimator.md), CSV, per-trial signal export and SVG plots.
#include <string>

#include <nlohmann/json.hpp>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

std::string format_text(const Report& r, const std::string& log_name);
nlohmann::json to_json(const Report& r, const std::string& log_name);
nlohmann::json settings_to_json(const EstimatorSettings& s);
// One row per (method, trial) and per summary. Throws std::runtime_error naming the file.
void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path);
// Per trial: t, Δx, Δẋ, Δẍ, Δu_ext (admittance and sensor), u_pert; needs keep_windows.
void export_signals(const Report& r, const std::string& dir);
// Fig. 3 (PSDs), Fig. 5 (variational dynamics per trial), D and K per angle, as SVG.
void write_plots(const Report& r, const std::string& dir);

// Loads estimator settings from YAML (config/estimator.yaml documents the
// keys). Unknown keys and bad values throw std::runtime_error("<file>: <key>: <reason>").
EstimatorSettings load_estimator_settings(const std::string& path, EstimatorSettings base = {});

}  // namespace manip::estimation
