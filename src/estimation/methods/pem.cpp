// pem (the default): pooled causal prediction error, maximum likelihood with
// a model of the person's own motion and motor noise (pem.hpp); sandwich SE.
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/pem.hpp"
#include "manip/estimation/settings.hpp"

namespace manip::estimation {
namespace {

class PredictionError final : public Method {
 public:
  std::string name() const override { return "pem"; }
  std::string description() const override {
    return "default: pooled causal prediction error (maximum likelihood) with a model of the person's own motion "
           "and motor noise; sandwich SE, 95% CI";
  }
  bool per_trial() const override { return false; }
  DataWindow windows() const override { return DataWindow::prediction_error; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    PemSettings ps = d.settings->pem;
    // Per angle, a few trials pin D, K in one direction but not the noise
    // model: hold the session's noise model and fit D, K only.
    if (r.session_fit && r.session_fit->disturbance) {
      ps.hold_disturbance = true;
      ps.fixed_disturbance = *r.session_fit->disturbance;
    }
    std::vector<OeWindow> pw;
    return fit_prediction_error(select(d.prediction_error, r.trials, pw), ps);
  }
};

}  // namespace

std::unique_ptr<Method> make_pem_method() { return std::make_unique<PredictionError>(); }

}  // namespace manip::estimation
