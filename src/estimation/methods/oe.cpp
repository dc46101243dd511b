// oe: pooled causal output error with a per-trial polynomial for the
// unperturbed movement (output_error.hpp); jackknife SE over trials.
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/settings.hpp"

namespace manip::estimation {
namespace {

class OutputError final : public Method {
 public:
  std::string name() const override { return "oe"; }
  std::string description() const override {
    return "pooled causal output error with a per-trial polynomial; jackknife SE, 95% CI";
  }
  bool per_trial() const override { return false; }
  DataWindow windows() const override { return DataWindow::output_error; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    std::vector<OeWindow> ow;
    return fit_output_error(select(d.output_error, r.trials, ow), d.settings->oe);
  }
};

}  // namespace

std::unique_ptr<Method> make_oe_method() { return std::make_unique<OutputError>(); }

}  // namespace manip::estimation
