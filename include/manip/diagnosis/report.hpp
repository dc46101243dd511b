#pragma once
// Text and JSON reports of a diagnosis (layout in docs/diagnosis.md).
#include <string>

#include <nlohmann/json.hpp>

#include "manip/diagnosis/engine.hpp"

namespace manip::diagnosis {

struct ReportContext {
  std::string front_end;     // e.g. "single-joint CSV"
  std::string preprocessing; // one line: smoother, sign decision
  std::string baseline_equation = "torque = I acc + B vel + K (x - x_ref) + c";
  std::string cv_units;      // e.g. "trials (both axes of a trial in one fold)"; empty: contiguous blocks
  std::string target_word = "torque";
  std::string extra_text;    // front-end specific sections, printed before the timing line
};

[[nodiscard]] std::string text_report(const Diagnosis& d, const ReportContext& ctx);
// A number as diagnose_model's text prints it (printf "%.4g").
[[nodiscard]] std::string g4(double v);
// One fitted parameter as every section of the JSON report has it: name,
// unit, value, ci95 [lo, hi], and its plausible range when it has one.
[[nodiscard]] nlohmann::json param_json(const ParamEstimate& p);
[[nodiscard]] nlohmann::json json_report(const Diagnosis& d, const ReportContext& ctx);

// The JSON "traces" section (docs/diagnosis.md, "Figures (--plots)") from the
// engine's held-out predictions (EngineOptions::keep_predictions):
//  single joint: one fold (the one of median baseline fold VAF), its first
//    <= 3 s: t_s, measured (the smoothed target the models predict), baseline, extended;
//  manipulandum: per time after onset (shared window), per axis: the mean
//    held-out residual over trials and its 95 % half-width (1.96 SD/sqrt(n)),
//    before and after; and three example trials (first, middle, last used).
// `matches_engine_folds`: the fold VAFs recomputed from the predictions equal the report's.
[[nodiscard]] nlohmann::json traces_json(const Dataset& d, const Diagnosis& res);

}  // namespace manip::diagnosis
