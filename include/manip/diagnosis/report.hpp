#pragma once
// Text and JSON reports of a diagnosis (layout in docs/diagnosis.md).
#include <string>

#include <nlohmann/json.hpp>

#include "manip/diagnosis/engine.hpp"

namespace manip::diagnosis {

struct ReportContext {
  std::string front_end;     // e.g. "single-joint CSV"
  std::string preprocessing; // one line: smoother, sign decision
};

[[nodiscard]] std::string text_report(const Diagnosis& d, const ReportContext& ctx);
[[nodiscard]] nlohmann::json json_report(const Diagnosis& d, const ReportContext& ctx);

}  // namespace manip::diagnosis
