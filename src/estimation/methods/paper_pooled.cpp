// paper-pooled: the paper's equation error (eq. 30-32) on the same isolated
// signals, one least-squares fit over all perturbed trials of the group.
#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/settings.hpp"

namespace manip::estimation {
namespace {

class PaperPooled final : public Method {
 public:
  std::string name() const override { return "paper-pooled"; }
  std::string description() const override {
    return "the paper's equation error, one fit over all perturbed trials; estimate (SE, 95% CI)";
  }
  bool per_trial() const override { return false; }
  DataWindow windows() const override { return DataWindow::variational; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    std::vector<VariationalWindow> vw;
    std::vector<Mat2> mb;
    return fit_equation_error(select(d.variational, r.trials, vw), select(d.m_bsp, r.trials, mb), d.settings->ls);
  }
};

}  // namespace

std::unique_ptr<Method> make_paper_pooled_method() { return std::make_unique<PaperPooled>(); }

}  // namespace manip::estimation
