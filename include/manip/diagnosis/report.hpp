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
[[nodiscard]] nlohmann::json json_report(const Diagnosis& d, const ReportContext& ctx);

}  // namespace manip::diagnosis
