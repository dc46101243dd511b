#include "manip/diagnosis/synthetic.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fstream>
#include <numbers>
#include <stdexcept>

#include "manip/common/errors.hpp"
#include "manip/common/rng.hpp"

namespace manip::diagnosis::synthetic {

const char* name(Hidden h) {
  switch (h) {
    case Hidden::none: return "none";
    case Hidden::reflex: return "stretch_reflex";
    case Hidden::quadratic_stiffness: return "quadratic_stiffness";
    case Hidden::offset_drift: return "offset_drift";
    case Hidden::friction: return "coulomb_friction";
    case Hidden::torque_lag: return "torque_lag";
    case Hidden::relaxation: return "stiffness_relaxation";
  }
  return "?";
}

const char* main_param_name(Hidden h) {
  switch (h) {
    case Hidden::reflex: return "delay";
    case Hidden::quadratic_stiffness: return "K2";
    case Hidden::offset_drift: return "drift_rate";
    case Hidden::friction: return "Fc";
    case Hidden::torque_lag: return "lag";
    case Hidden::relaxation: return "tau_relax";
    case Hidden::none: break;
  }
  return "";
}

double Truth::main_param(Hidden h) const {
  switch (h) {
    case Hidden::reflex: return delay_s;
    case Hidden::quadratic_stiffness: return K2;
    case Hidden::offset_drift: return drift_rate;
    case Hidden::friction: return Fc;
    case Hidden::torque_lag: return lag_s;
    case Hidden::relaxation: return tau_relax_s;
    case Hidden::none: break;
  }
  return 0.0;
}

namespace {
// One step of y' = (u - y) / lag with u linear between samples (first-order
// hold; exact): the particular solution u_k + s (t - lag), s the input's slope.
double first_order_lag_step(double y, double u0, double u1, double lag, double dt) {
  const double a = std::exp(-dt / lag);
  return a * y + (1.0 - a) * u0 + (u1 - u0) * (1.0 - lag / dt * (1.0 - a));
}
}  // namespace

Generated generate(const Options& opt) {
  PortableRng rng(opt.seed * 0x9E3779B97F4A7C15ull + static_cast<std::uint64_t>(opt.hidden) + 17);
  Generated g;
  Truth& t = g.truth;
  // Ankle under tonic contraction (Kearney et al. 1997; Mirbagheri et al. 2000):
  // I 0.015-0.025 kg m^2 (foot + pedal), B 0.5-1.5 N m s/rad, K 80-250 N m/rad.
  t.I = rng.uniform(0.015, 0.025);
  t.B = rng.uniform(0.5, 1.5);
  t.K = rng.uniform(80.0, 250.0);
  t.c = rng.uniform(-10.0, 10.0);
  t.torque_sign = rng.uniform() < 0.5 ? -1 : 1;
  t.noise_white_nm = 0.3;     // torque-cell noise
  t.noise_coloured_nm = 0.5;  // slow fluctuation of the tonic contraction (1 Hz first-order)
  const double dt = opt.dt_s;
  const auto n = static_cast<std::size_t>(std::lround(opt.duration_s / dt));
  constexpr int sub = 10;
  const double h = dt / sub;
  // Pseudo-random multi-level position input (like the lab's): a new level
  // uniform in +-0.03 rad after a hold of 50-400 ms, tracked by a position
  // servo modelled as a second-order system (12 Hz, damping 0.7).
  const double x0 = rng.uniform(-0.05, 0.1);
  const double wa = 2.0 * std::numbers::pi * 12.0, za = 0.7;
  double level = x0, hold_left = 0.0;
  double x = x0, v = 0.0;
  // Reflex state and delay line (substep resolution).
  if (opt.hidden == Hidden::reflex) {
    t.delay_s = rng.uniform(0.030, 0.060);
    t.fn_hz = rng.uniform(2.0, 6.0);
    t.zeta = rng.uniform(0.6, 1.0);
    t.reflex_dir = rng.uniform() < 0.5 ? -1 : 1;
  }
  if (opt.hidden == Hidden::friction) t.v_s = 0.003 * std::pow(10.0, rng.uniform());  // 3-30 mrad/s
  const auto dsub = static_cast<std::size_t>(std::lround(t.delay_s / h));
  std::deque<double> vline(dsub + 1, 0.0);
  const double wr = 2.0 * std::numbers::pi * std::max(t.fn_hz, 1e-9);
  double r = 0.0, rd = 0.0;  // reflex LP state (unit gain)
  double col = 0.0;
  const double a_col = std::exp(-2.0 * std::numbers::pi * 1.0 * dt);
  std::vector<double> pos(n), vel(n), acc(n), refl(n), time(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (hold_left <= 0.0) {
      level = x0 + rng.uniform(-0.03, 0.03);
      hold_left = rng.uniform(0.05, 0.4);
    }
    for (int k = 0; k < sub; ++k) {
      // RK4 on (x, v, r, rd); the reflex input (delayed rectified velocity) is held over the substep.
      const double u_ref = std::max(t.reflex_dir * vline.front(), 0.0);
      auto f = [&](const std::array<double, 4>& s) {
        return std::array<double, 4>{s[1], wa * wa * (level - s[0]) - 2.0 * za * wa * s[1], s[3],
                                     wr * wr * (u_ref - s[2]) - 2.0 * t.zeta * wr * s[3]};
      };
      const std::array<double, 4> s0{x, v, r, rd};
      auto add = [](const std::array<double, 4>& a, const std::array<double, 4>& b, double c) {
        return std::array<double, 4>{a[0] + c * b[0], a[1] + c * b[1], a[2] + c * b[2], a[3] + c * b[3]};
      };
      const auto k1 = f(s0);
      const auto k2 = f(add(s0, k1, h / 2));
      const auto k3 = f(add(s0, k2, h / 2));
      const auto k4 = f(add(s0, k3, h));
      x += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]);
      v += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]);
      r += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]);
      rd += h / 6 * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3]);
      vline.push_back(v);
      vline.pop_front();
    }
    hold_left -= dt;
    pos[i] = x;
    vel[i] = v;
    acc[i] = wa * wa * (level - x) - 2.0 * za * wa * v;
    refl[i] = t.reflex_dir * r;
    time[i] = static_cast<double>(i) * dt;
  }
  double xm = 0;
  for (double p : pos) xm += p;
  xm /= static_cast<double>(n);
  // Intrinsic torque and its RMS (about its mean): the magnitude scale.
  std::vector<double> intr(n);
  double im = 0, irms = 0;
  for (std::size_t i = 0; i < n; ++i) {
    intr[i] = t.I * acc[i] + t.B * vel[i] + t.K * (pos[i] - xm);
    im += intr[i];
  }
  im /= static_cast<double>(n);
  for (double q : intr) irms += (q - im) * (q - im);
  irms = std::sqrt(irms / static_cast<double>(n));
  // Hidden term (unit-scaled shape, then scaled to the target RMS).
  std::vector<double> hid(n, 0.0);
  const double T = opt.duration_s;
  for (std::size_t i = 0; i < n; ++i) {
    switch (opt.hidden) {
      case Hidden::reflex: hid[i] = refl[i]; break;
      case Hidden::quadratic_stiffness: hid[i] = (pos[i] - xm) * (pos[i] - xm); break;
      case Hidden::offset_drift: hid[i] = time[i] - T / 2; break;
      case Hidden::friction: hid[i] = std::tanh(vel[i] / t.v_s); break;
      case Hidden::relaxation: break;  // below: a filter over the whole record
      case Hidden::torque_lag:
      case Hidden::none: break;
    }
  }
  if (opt.hidden == Hidden::relaxation) {
    // The true position (not the engine's smoothed one) through the
    // continuous first-order low pass, exact for an input linear between
    // samples; the term is what the low pass has not caught up with.
    t.tau_relax_s = 0.3 * std::pow(10.0, rng.uniform());  // 0.3-3 s
    double lp = pos[0] - xm;
    for (std::size_t i = 0; i < n; ++i) {
      if (i > 0) lp = first_order_lag_step(lp, pos[i - 1] - xm, pos[i] - xm, t.tau_relax_s, dt);
      hid[i] = pos[i] - xm - lp;
    }
  }
  if (opt.hidden == Hidden::torque_lag) {
    // The lag's hidden term is LP_T[intrinsic] - intrinsic, nonlinear in T:
    // T is found by bisection (the term's RMS grows monotonically with T)
    // so that its RMS is the magnitude's share of the intrinsic RMS.
    const double target = opt.magnitude * irms * rng.uniform(0.8, 1.25);
    auto term_rms = [&](double lag) {
      double y = intr[0], acc2 = 0.0;
      for (std::size_t i = 1; i < n; ++i) {
        y = first_order_lag_step(y, intr[i - 1], intr[i], lag, dt);
        acc2 += (y - intr[i]) * (y - intr[i]);
      }
      return std::sqrt(acc2 / static_cast<double>(n));
    };
    double lo = 0.0, hi = 0.2;
    if (opt.lag_s > 0.0) lo = hi = opt.lag_s;  // given: no search
    for (int it = 0; it < 60 && opt.lag_s <= 0.0; ++it) {
      const double mid = 0.5 * (lo + hi);
      (term_rms(mid) < target ? lo : hi) = mid;
    }
    t.lag_s = 0.5 * (lo + hi);
  }
  if (opt.hidden != Hidden::none && opt.hidden != Hidden::torque_lag) {
    double hm = 0, hr = 0;
    for (double q : hid) hm += q;
    hm /= static_cast<double>(n);
    for (double q : hid) hr += (q - hm) * (q - hm);
    hr = std::sqrt(hr / static_cast<double>(n));
    const double scale = opt.magnitude * irms * rng.uniform(0.8, 1.25) / hr;
    for (auto& q : hid) q *= scale;
    switch (opt.hidden) {
      case Hidden::reflex: t.reflex_gain = scale; break;
      case Hidden::quadratic_stiffness: t.K2 = scale; break;
      case Hidden::offset_drift: t.drift_rate = scale; break;
      case Hidden::friction: t.Fc = scale; break;
      case Hidden::relaxation: t.dK = scale; break;
      case Hidden::torque_lag:
      case Hidden::none: break;
    }
  }
  auto& rec = g.record;
  rec.source = std::string("synthetic:") + name(opt.hidden) + ":seed" + std::to_string(opt.seed);
  rec.dt_s = dt;
  rec.pos_rad.resize(n);
  rec.torque_nm.resize(n);
  // The joint torque (intrinsic, hidden term, the contraction's slow
  // fluctuation); a torque-channel lag filters all of it, the cell's white
  // noise enters after the filter.
  double lagged = 0.0, prev_joint = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    col = a_col * col + std::sqrt(1.0 - a_col * a_col) * t.noise_coloured_nm * rng.normal();
    const double joint = t.c + intr[i] + hid[i] + col;
    lagged = i == 0 || t.lag_s <= 0.0 ? joint : first_order_lag_step(lagged, prev_joint, joint, t.lag_s, dt);
    prev_joint = joint;
    const double tq = lagged + t.noise_white_nm * rng.normal();
    rec.torque_nm[i] = t.torque_sign * tq;
    rec.pos_rad[i] = pos[i] + 2e-5 * rng.normal();  // encoder noise
  }
  // The intrinsic model is about the record's mean position; report c there.
  return g;
}

void write_csv(const SingleJointRecord& rec, const std::string& path, bool with_time_column) {
  std::ofstream o(path);
  if (!o) throw OutputError(path + ": cannot be written");
  char buf[96];
  if (with_time_column) {
    o << "# synthetic single-joint record\ntime_s,pos_rad,torque_nm\n";
  } else {
    std::snprintf(buf, sizeof buf, "# dt=%.17g; channels=['pos1', 'tq1']\n", rec.dt_s);
    o << buf;
  }
  for (std::size_t i = 0; i < rec.pos_rad.size(); ++i) {
    if (with_time_column) {
      std::snprintf(buf, sizeof buf, "%.9g,%.10g,%.10g\n", static_cast<double>(i) * rec.dt_s, rec.pos_rad[i], rec.torque_nm[i]);
    } else {
      std::snprintf(buf, sizeof buf, "%.10g,%.10g\n", rec.pos_rad[i], rec.torque_nm[i]);
    }
    o << buf;
  }
  if (!o) throw OutputError(path + ": write failed");
}

}  // namespace manip::diagnosis::synthetic
