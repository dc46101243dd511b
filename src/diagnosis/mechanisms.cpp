#include "manip/diagnosis/mechanisms.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <memory>
#include <numbers>

#include "manip/dsp/sosfilt.hpp"

namespace manip::diagnosis {

void Dataset::smooth(const std::vector<double>& x, std::vector<double>& y) const {
  y.resize(x.size());
  if (smoother) {
    smoother->apply(x, y);
  } else {
    std::copy(x.begin(), x.end(), y.begin());
  }
}

void Mechanism::for_each_setting(const Dataset& d, const std::function<void(std::size_t, const Columns&)>& f) const {
  const auto g = grid(d);
  for (std::size_t s = 0; s < g.size(); ++s) f(s, columns(d, g[s]));
}

std::array<double, 6> reflex_lowpass_sos(double fn_hz, double zeta, double dt_s) {
  const double w = 2.0 * std::numbers::pi * fn_hz;
  const double k = w / std::tan(w * dt_s / 2.0);  // prewarped bilinear transform
  const double a0 = k * k + 2.0 * zeta * w * k + w * w;
  const double a1 = 2.0 * (w * w - k * k);
  const double a2 = k * k - 2.0 * zeta * w * k + w * w;
  const double b = w * w / a0;
  return {b, 2.0 * b, b, 1.0, a1 / a0, a2 / a0};
}

namespace {

// Physiological search range of the reflex shape (docs/diagnosis.md, "Stretch reflex"):
// - loop delay 20-100 ms: brackets the short-latency stretch reflex of the
//   ankle muscles (EMG latency ~40 ms, torque delay 40-50 ms: Kearney, Stein &
//   Parameswaran 1997; Mirbagheri et al. 2000) and the medium-latency response;
// - low-pass corner 1-25 Hz, damping 0.5-1: the reflex torque follows muscle
//   activation through twitch dynamics, a critically damped second-order
//   system with corner ~1/(2 pi T_c); twitch contraction times T_c of 40-150 ms
//   (fast to slow, soleus being slow) give ~1-4 Hz, and the upper end leaves
//   room for faster pathways.
constexpr double kDelayLo_s = 0.020, kDelayHi_s = 0.100;
constexpr double kFnLo_hz = 1.0, kFnHi_hz = 25.0;
constexpr int kFnCount = 12;
constexpr double kZetas[] = {0.5, 0.75, 1.0};

class StretchReflexImpl final : public Mechanism {
 public:
  std::string id() const override { return "stretch_reflex"; }
  std::string title() const override {
    return "stretch reflex: delayed, half-wave rectified velocity -> low pass (Hammerstein)";
  }
  std::string signature() const override {
    return "residual correlates with velocity delayed by tens of ms, more in one direction of stretch";
  }
  std::vector<ParamInfo> shape_params() const override {
    return {{"delay", "s", kDelayLo_s, kDelayHi_s}, {"fn", "Hz", kFnLo_hz, kFnHi_hz}, {"zeta", "1", 0.5, 1.0}};
  }
  bool searchable_off_grid() const override { return true; }
  std::vector<ParamInfo> gains() const override {
    // Positive = resisting stretch in that direction (columns below are signed so).
    return {{"gain_pos_vel", "N m s/rad", 0.0, 50.0}, {"gain_neg_vel", "N m s/rad", 0.0, 50.0}};
  }
  int main_param() const override { return 0; }
  std::vector<double> fns() const {
    std::vector<double> f(kFnCount);
    for (int i = 0; i < kFnCount; ++i)
      f[static_cast<std::size_t>(i)] = kFnLo_hz * std::pow(kFnHi_hz / kFnLo_hz, i / (kFnCount - 1.0));
    return f;
  }
  // Delays on a 1 ms grid at any sampling rate: every round(1 ms / dt)-th
  // whole sample when dt <= 1 ms, else fractional delays (linear
  // interpolation between samples, below), so that a record sampled at
  // 100 Hz - the rate such records are often analysed at - does not
  // quantise the loop delay to 10 ms.
  std::vector<double> delays(const Dataset& d) const {
    std::vector<double> out;
    if (d.dt_s <= 0.001) {
      const auto step = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(0.001 / d.dt_s)));
      const auto lo = static_cast<std::size_t>(std::lround(kDelayLo_s / d.dt_s));
      const auto hi = static_cast<std::size_t>(std::lround(kDelayHi_s / d.dt_s));
      for (std::size_t k = lo; k <= hi; k += step) out.push_back(static_cast<double>(k) * d.dt_s);
    } else {
      const auto n = static_cast<int>(std::lround((kDelayHi_s - kDelayLo_s) / 0.001));
      for (int i = 0; i <= n; ++i) out.push_back(kDelayLo_s + 0.001 * i);
    }
    return out;
  }
  std::vector<std::vector<double>> grid(const Dataset& d) const override {
    std::vector<std::vector<double>> g;
    for (double fn : fns())
      for (double z : kZetas)
        for (double t : delays(d)) g.push_back({t, fn, z});
    return g;
  }
  std::size_t history_samples(const Dataset& d) const override {
    // delay plus ~5 time constants of the slowest low pass (its zero-state transient)
    const double settle = 5.0 / (kZetas[0] * 2.0 * std::numbers::pi * kFnLo_hz);
    return static_cast<std::size_t>(std::ceil((kDelayHi_s + settle) / d.dt_s));
  }
  // Rectified, smoothed velocity of each segment: [seg][dir]
  std::vector<std::array<std::vector<double>, 2>> rectified(const Dataset& d) const {
    std::vector<std::array<std::vector<double>, 2>> out(d.segments.size());
    for (std::size_t s = 0; s < d.segments.size(); ++s) {
      const auto& v = d.segments[s].vel;
      std::vector<double> p(v.size()), n(v.size());
      for (std::size_t i = 0; i < v.size(); ++i) {
        p[i] = std::max(v[i], 0.0);
        n[i] = std::min(v[i], 0.0);
      }
      d.smooth(p, out[s][0]);
      d.smooth(n, out[s][1]);
    }
    return out;
  }
  static void lowpass(const std::array<double, 6>& c, const std::vector<double>& x, std::vector<double>& y) {
    const dsp::Sos sos{c[0], c[1], c[2], c[3], c[4], c[5]};
    y.resize(x.size());
    dsp::sosfilt(std::span<const dsp::Sos>(&sos, 1), x, y);
  }
  // y(t) = x(t - delay), zero before the delay; between samples linear.
  static void shift(const std::vector<double>& x, double delay_s, double dt_s, std::vector<double>& y) {
    y.assign(x.size(), 0.0);
    const double q = delay_s / dt_s;
    if (std::fabs(q - std::round(q)) < 1e-6) {  // whole samples (every grid point when dt <= 1 ms)
      const auto k = static_cast<std::size_t>(std::lround(q));
      if (k < x.size()) std::copy(x.begin(), x.end() - static_cast<long>(k), y.begin() + static_cast<long>(k));
      return;
    }
    const auto k = static_cast<std::size_t>(std::floor(q));
    const double w = q - static_cast<double>(k);
    for (std::size_t i = k + 1; i < x.size(); ++i) y[i] = (1.0 - w) * x[i - k] + w * x[i - k - 1];
  }
  Columns columns(const Dataset& d, std::span<const double> setting) const override { return columns_from(rectified(d), d.dt_s, setting); }
  // The low pass and the delay are both linear and time-invariant from a
  // zero state, so they commute: the low pass runs first (as in
  // for_each_setting) and a setting that differs from a recent one only in
  // its delay reuses that low pass's output. The search between grid points
  // moves one or more axes at a time and its replicates revisit the same
  // (f_n, zeta) pairs, so the recursive filter - ~60 % of a new setting's
  // cost on a 60 s, 1 kHz record - runs about once per pair instead of once
  // per setting; the columns are bit for bit those of columns().
  std::function<Columns(std::span<const double>)> columns_of(const Dataset& d) const override {
    struct Filtered {
      double fn_hz, zeta;
      std::vector<std::array<std::vector<double>, 2>> y;  // [seg][dir]
    };
    struct State {
      std::vector<std::array<std::vector<double>, 2>> rect;
      std::deque<Filtered> recent;  // most recently used first
      std::size_t capacity = 1;
    };
    auto st = std::make_shared<State>();
    st->rect = rectified(d);
    std::size_t samples = 0;
    for (const auto& r : st->rect) samples += 2 * r[0].size();
    // At most ~64 MB of filtered signals (64 pairs of a 60 s, 1 kHz record).
    constexpr std::size_t kBudgetDoubles = std::size_t{8} << 20;
    st->capacity = std::max<std::size_t>(1, kBudgetDoubles / std::max<std::size_t>(1, samples));
    return [st, dt = d.dt_s](std::span<const double> setting) {
      auto it = std::find_if(st->recent.begin(), st->recent.end(),
                             [&](const Filtered& f) { return f.fn_hz == setting[1] && f.zeta == setting[2]; });
      if (it == st->recent.end()) {
        Filtered f{setting[1], setting[2], std::vector<std::array<std::vector<double>, 2>>(st->rect.size())};
        const auto c = reflex_lowpass_sos(setting[1], setting[2], dt);
        for (std::size_t s = 0; s < st->rect.size(); ++s)
          for (std::size_t dir = 0; dir < 2; ++dir) lowpass(c, st->rect[s][dir], f.y[s][dir]);
        if (st->recent.size() >= st->capacity) st->recent.pop_back();
        st->recent.push_front(std::move(f));
      } else if (it != st->recent.begin()) {
        Filtered f = std::move(*it);
        st->recent.erase(it);
        st->recent.push_front(std::move(f));
      }
      const auto& y = st->recent.front().y;
      Columns out(y.size(), std::vector<std::vector<double>>(2));
      for (std::size_t s = 0; s < y.size(); ++s)
        for (std::size_t dir = 0; dir < 2; ++dir) shift(y[s][dir], setting[0], dt, out[s][dir]);
      return out;
    };
  }
  static Columns columns_from(const std::vector<std::array<std::vector<double>, 2>>& rect, double dt_s, std::span<const double> setting) {
    const auto c = reflex_lowpass_sos(setting[1], setting[2], dt_s);
    Columns out(rect.size(), std::vector<std::vector<double>>(2));
    std::vector<double> tmp;
    for (std::size_t s = 0; s < rect.size(); ++s)
      for (std::size_t dir = 0; dir < 2; ++dir) {
        lowpass(c, rect[s][dir], tmp);
        shift(tmp, setting[0], dt_s, out[s][dir]);
      }
    return out;
  }
  void for_each_setting(const Dataset& d, const std::function<void(std::size_t, const Columns&)>& f) const override {
    const auto rect = rectified(d);
    const auto ds = delays(d);
    std::size_t idx = 0;
    Columns cols(d.segments.size(), std::vector<std::vector<double>>(2));
    std::vector<std::array<std::vector<double>, 2>> filt(d.segments.size());
    for (double fn : fns())
      for (double z : kZetas) {
        const auto c = reflex_lowpass_sos(fn, z, d.dt_s);
        for (std::size_t s = 0; s < d.segments.size(); ++s)
          for (std::size_t dir = 0; dir < 2; ++dir) lowpass(c, rect[s][dir], filt[s][dir]);
        for (double t : ds) {
          for (std::size_t s = 0; s < d.segments.size(); ++s)
            for (std::size_t dir = 0; dir < 2; ++dir) shift(filt[s][dir], t, d.dt_s, cols[s][dir]);
          f(idx++, cols);
        }
      }
  }
};

// Columns from a pointwise function of the segment's signals, then smoothed.
template <class F>
Columns pointwise(const Dataset& d, F fn) {
  Columns out(d.segments.size(), std::vector<std::vector<double>>(1));
  std::vector<double> raw;
  for (std::size_t s = 0; s < d.segments.size(); ++s) {
    const auto& seg = d.segments[s];
    raw.resize(seg.pos.size());
    for (std::size_t i = 0; i < raw.size(); ++i) raw[i] = fn(seg, i);
    d.smooth(raw, out[s][0]);
  }
  return out;
}

class QuadraticStiffnessImpl final : public Mechanism {
 public:
  std::string id() const override { return "quadratic_stiffness"; }
  std::string title() const override { return "position-dependent stiffness: K2 (x - x_ref)^2"; }
  std::string signature() const override {
    return "residual correlates with the squared position deviation (asymmetric elastic torque)";
  }
  std::vector<ParamInfo> gains() const override {
    // No published bound on this coefficient: the range keeps the stiffness
    // change 2 K2 dx within +-1000 N m/rad over dx = +-0.1 rad (ankle K is
    // 10-500 N m/rad with contraction: Kearney et al. 1997, Mirbagheri et al. 2000).
    return {{"K2", "N m/rad^2", -5000.0, 5000.0}};
  }
  int main_param() const override { return 0; }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    const double ref = d.pos_ref;
    return pointwise(d, [ref](const Segment& s, std::size_t i) { return (s.pos[i] - ref) * (s.pos[i] - ref); });
  }
};

// Stiffness that relaxes: the elastic torque of a held position decays over
// tau towards a lower static value (a standard linear solid: K for slow
// motion, K + dK for motion faster than tau). Two physical routes give this
// form and the record cannot tell them apart: stress relaxation of active
// muscle and tendon (time constants of 0.1 s to several seconds: e.g. Rack &
// Westbury 1974 for the loss of short-range stiffness, Fung's quasi-linear
// viscoelasticity for tissue), and a participant who holds a tonic torque
// (often against a torque display) correcting slow torque changes
// voluntarily, which removes the slow part of the elastic torque (voluntary
// reaction times >= 150 ms set the lower end). The column is
// dK (x_c - LP_tau[x_c]) = dK HP_tau[x_c], x_c = x - x_ref: a high pass of
// the position, so a constant or a ramp of the torque (offset, drift) is not
// in it, and for tau -> infinity it becomes dK x_c (K itself).
class StiffnessRelaxationImpl final : public Mechanism {
 public:
  std::string id() const override { return "stiffness_relaxation"; }
  std::string title() const override {
    return "stiffness that relaxes over tau (stress relaxation, or slow voluntary torque regulation): dK HP_tau[x - x_ref]";
  }
  std::string signature() const override {
    return "residual follows the position's deviation from its running mean over tau: the static stiffness is below the stiffness to fast motion";
  }
  std::vector<ParamInfo> shape_params() const override { return {{"tau_relax", "s", kTauLo_s, kTauHi_s}}; }
  bool searchable_off_grid() const override { return true; }
  std::vector<std::vector<double>> grid(const Dataset&) const override {
    std::vector<std::vector<double>> g;
    for (int i = 0; i < kTauCount; ++i) g.push_back({kTauLo_s * std::pow(kTauHi_s / kTauLo_s, i / (kTauCount - 1.0))});
    return g;
  }
  std::vector<ParamInfo> gains() const override {
    // dK > 0: the stiffness to fast motion exceeds the static one (a
    // relaxation; a dK < 0 would be a stiffness that grows while the
    // position is held). The size bound is the range of ankle K itself
    // (10-500 N m/rad with contraction: Kearney et al. 1997, Mirbagheri et al. 2000).
    return {{"dK", "N m/rad", 0.0, 500.0}};
  }
  int main_param() const override { return 0; }
  BaseSum base_sum() const override {
    return {"K", "dK", "K_fast", "K + dK: the stiffness to motion faster than tau_relax (K is then the static stiffness)"};
  }
  Columns columns(const Dataset& d, std::span<const double> setting) const override {
    // Exact first-order recursion of the low pass; started at the first
    // sample's position (at rest there: no start-up transient in the column).
    const double a = std::exp(-d.dt_s / setting[0]);
    Columns out(d.segments.size(), std::vector<std::vector<double>>(1));
    for (std::size_t s = 0; s < d.segments.size(); ++s) {
      const auto& x = d.segments[s].pos;  // already smoothed like the target
      auto& c = out[s][0];
      c.resize(x.size());
      double lp = x.empty() ? 0.0 : x.front() - d.pos_ref;
      for (std::size_t i = 0; i < x.size(); ++i) {
        const double xc = x[i] - d.pos_ref;
        lp = a * lp + (1.0 - a) * xc;
        c[i] = xc - lp;
      }
    }
    return out;
  }

 private:
  // 0.1-10 s, 41 points (ratio 1.12): above the reflex's low pass, below a
  // record's length; a tau on the edge is refused as outside this range.
  static constexpr double kTauLo_s = 0.1, kTauHi_s = 10.0;
  static constexpr int kTauCount = 41;
};

class OffsetDriftImpl final : public Mechanism {
 public:
  std::string id() const override { return "offset_drift"; }
  std::string title() const override { return "torque-sensor offset drift: r (t - t_mid)"; }
  std::string signature() const override { return "residual correlates with time (slow trend)"; }
  std::vector<ParamInfo> gains() const override {
    // Strain-gauge torque cells drift by far less than 1 N m per minute once warm;
    // the bound flags anything larger as something else (e.g. fatigue).
    return {{"drift_rate", "N m/s", -1.0, 1.0}};
  }
  int main_param() const override { return 0; }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    double t_lo = 1e300, t_hi = -1e300;
    for (const auto& s : d.segments) {
      t_lo = std::min(t_lo, s.t0_s);
      t_hi = std::max(t_hi, s.t0_s + static_cast<double>(s.y.size()) * d.dt_s);
    }
    const double mid = 0.5 * (t_lo + t_hi), dt = d.dt_s;
    return pointwise(d, [mid, dt](const Segment& s, std::size_t i) { return s.t0_s + static_cast<double>(i) * dt - mid; });
  }
};

class CoulombFrictionImpl final : public Mechanism {
 public:
  std::string id() const override { return "coulomb_friction"; }
  std::string title() const override { return "Coulomb-like friction: Fc tanh(v / v_s)"; }
  std::string signature() const override {
    return "residual correlates with the sign of velocity (a step at every reversal)";
  }
  // A pure sign(v) is undefined during holds, where the measured velocity is
  // noise; the smooth Coulomb law tanh(v / v_s) (e.g. Olsson et al. 1998,
  // "Friction models and friction compensation") has a transition velocity
  // v_s, searched over 2-50 mrad/s (below the perturbation's velocities of
  // 0.1-3 rad/s, above an encoder's velocity noise).
  std::vector<ParamInfo> shape_params() const override { return {{"v_s", "rad/s", 0.002, 0.05}}; }
  bool searchable_off_grid() const override { return true; }
  std::vector<std::vector<double>> grid(const Dataset&) const override {
    return {{0.002}, {0.005}, {0.01}, {0.02}, {0.05}};
  }
  std::vector<ParamInfo> gains() const override {
    // Friction of a pedal/ankle-orthosis bearing: well below 5 N m.
    return {{"Fc", "N m", 0.0, 5.0}};
  }
  int main_param() const override { return 1; }
  Columns columns(const Dataset& d, std::span<const double> setting) const override {
    const double vs = setting[0];
    return pointwise(d, [vs](const Segment& s, std::size_t i) { return std::tanh(s.vel[i] / vs); });
  }
};

class WrongInertiaImpl final : public Mechanism {
 public:
  std::string id() const override { return "wrong_inertia"; }
  std::string title() const override { return "inertia different from the configured one: dI * acceleration"; }
  std::string signature() const override { return "residual correlates with acceleration"; }
  std::string not_applicable(const Dataset& d) const override {
    return d.inertia_fixed ? std::string{} : std::string{"inertia is fitted by the baseline (give --inertia to fix it)"};
  }
  std::vector<ParamInfo> gains() const override {
    // Foot + pedal inertia about the ankle is ~0.01-0.05 kg m^2 (Kearney et al. 1997).
    return {{"dI", "kg m^2", -0.05, 0.05}};
  }
  int main_param() const override { return 0; }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    Columns out(d.segments.size(), std::vector<std::vector<double>>(1));
    for (std::size_t s = 0; s < d.segments.size(); ++s) out[s][0] = d.segments[s].acc;
    return out;
  }
};

}  // namespace

std::vector<std::unique_ptr<Mechanism>> standard_library() {
  std::vector<std::unique_ptr<Mechanism>> lib;
  lib.push_back(std::make_unique<StretchReflexImpl>());
  lib.push_back(std::make_unique<QuadraticStiffnessImpl>());
  lib.push_back(std::make_unique<StiffnessRelaxationImpl>());
  lib.push_back(std::make_unique<OffsetDriftImpl>());
  lib.push_back(std::make_unique<CoulombFrictionImpl>());
  lib.push_back(std::make_unique<WrongInertiaImpl>());
  return lib;
}

}  // namespace manip::diagnosis
