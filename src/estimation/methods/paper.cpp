// paper: the paper's estimator, equation error per trial on high-pass-isolated
// signals (§3, eq. 30-32), summarised as mean (std) over trials like Table 1.
#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/settings.hpp"

namespace manip::estimation {
namespace {

class Paper final : public Method {
 public:
  std::string name() const override { return "paper"; }
  std::string description() const override {
    return "the paper's estimator: per-trial equation error on high-pass-isolated signals (eq. 30-32); mean (std) over trials";
  }
  bool per_trial() const override { return true; }
  DataWindow windows() const override { return DataWindow::variational; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    std::vector<VariationalWindow> vw;
    std::vector<Mat2> mb;
    return fit_equation_error(select(d.variational, r.trials, vw), select(d.m_bsp, r.trials, mb), d.settings->ls);
  }
};

}  // namespace

std::unique_ptr<Method> make_paper_method() { return std::make_unique<Paper>(); }

}  // namespace manip::estimation
