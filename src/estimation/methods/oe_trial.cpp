// oe-trial: the output-error fit (output_error.hpp) per trial; mean (std)
// over trials. One trial has no jackknife: its least-squares SE is kept.
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/settings.hpp"

namespace manip::estimation {
namespace {

class OutputErrorPerTrial final : public Method {
 public:
  std::string name() const override { return "oe-trial"; }
  std::string description() const override { return "the output-error fit per trial; mean (std) over trials"; }
  bool per_trial() const override { return true; }
  DataWindow windows() const override { return DataWindow::output_error; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    OeSettings o = d.settings->oe;
    o.jackknife = false;
    std::vector<OeWindow> ow;
    return fit_output_error(select(d.output_error, r.trials, ow), o);
  }
};

}  // namespace

std::unique_ptr<Method> make_oe_trial_method() { return std::make_unique<OutputErrorPerTrial>(); }

}  // namespace manip::estimation
