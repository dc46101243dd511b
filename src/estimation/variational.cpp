#include "manip/estimation/variational.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "manip/dsp/dsp.hpp"

namespace manip::estimation {
namespace {

// Axis `a` of a vector of Vec2 as a contiguous series.
std::vector<double> axis(const std::vector<Vec2>& v, int a) {
  std::vector<double> out(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) out[i] = v[i](a);
  return out;
}

std::string trial_name(const TrialData& t) { return "trial " + std::to_string(t.trial); }

}  // namespace

int sg_window_for(const PipelineSettings& s, double fs_hz) {
  return s.sg_window > 0 ? s.sg_window : dsp::savgol_window_for_cutoff(fs_hz, s.sg_cutoff_hz, s.sg_order);
}

VariationalWindow isolate_variational(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s) {
  return isolate_variational(info, trial, s, {});
}

VariationalWindow isolate_variational(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s,
                                      std::span<const double> jerk_x2) {
  const double fs = info.sample_rate_hz;
  const double dt = 1.0 / fs;
  if (trial.onset_index < 0) throw std::invalid_argument(trial_name(trial) + ": no perturbation onset");
  const auto n_win = static_cast<std::size_t>(std::llround(s.t_est_s * fs)) + 1;
  const auto on = static_cast<std::size_t>(trial.onset_index);
  if (on + n_win > trial.size())
    throw std::invalid_argument(trial_name(trial) + ": ends " + std::to_string((trial.size() - on) * dt) +
                                " s after onset, shorter than the " + std::to_string(s.t_est_s) + " s window");
  const int win = sg_window_for(s, fs);
  const auto sos = dsp::butter(s.hp_order, s.hp_cutoff_hz, fs, dsp::BandType::highpass);
  const auto padlen = static_cast<std::size_t>(dsp::sosfiltfilt_padlen(sos));
  if (trial.size() < static_cast<std::size_t>(win) || trial.size() <= padlen)
    throw std::invalid_argument(trial_name(trial) + ": " + std::to_string(trial.size()) +
                                " samples, too short for the SG window " + std::to_string(win));
  const dsp::SavgolFilter jerk_filter(win, s.sg_order, 3, dt);
  const dsp::SavgolFilter rate_filter(win, s.sg_order, 1, dt);

  VariationalWindow w;
  w.trial = trial.trial;
  w.fs_hz = fs;
  w.angle_rad = trial.angle_rad;
  w.x_onset_m = trial.x_m[on];
  w.dx.assign(n_win, Vec2::Zero());
  w.dxd = w.dx;
  w.dxdd = w.dx;
  w.du_ext_adm = w.dx;
  w.du_ext_force = w.dx;
  w.u_pert.assign(trial.u_pert_n.begin() + static_cast<std::ptrdiff_t>(on),
                  trial.u_pert_n.begin() + static_cast<std::ptrdiff_t>(on + n_win));

  const Mat2 m_handle = info.m_handle_shoulder_kg();
  const Mat2 d_adm = info.d_adm_shoulder_nspm();
  const Mat2 m_dev = info.m_adm_shoulder_kg() + m_handle;
  std::vector<double> buf(trial.size()), hp(trial.size()), acc(n_win), vel(n_win), pos(n_win), dfs(n_win);
  for (int a = 0; a < 2; ++a) {
    // Jerk -> high-pass -> integrate from onset (§3.1).
    if (a == 1 && jerk_x2.size() == trial.size()) {
      std::copy(jerk_x2.begin(), jerk_x2.end(), buf.begin());  // the caller's, by the same filter
    } else {
      jerk_filter.apply(axis(trial.x_m, a), buf);
    }
    dsp::sosfiltfilt(sos, buf, hp);
    dsp::cumulative_trapezoid(std::span<const double>(hp).subspan(on, n_win), dt, acc);
    dsp::cumulative_trapezoid(acc, dt, vel);
    dsp::cumulative_trapezoid(vel, dt, pos);
    // Force rate -> high-pass -> integrate once: Δf_s.
    const auto fa = axis(trial.f_sensor_n, a);
    rate_filter.apply(fa, buf);
    dsp::sosfiltfilt(sos, buf, hp);
    dsp::cumulative_trapezoid(std::span<const double>(hp).subspan(on, n_win), dt, dfs);
    for (std::size_t k = 0; k < n_win; ++k) {
      w.dxdd[k](a) = acc[k];
      w.dxd[k](a) = vel[k];
      w.dx[k](a) = pos[k];
      w.du_ext_force[k](a) = dfs[k];  // Δf_s for now, completed below
    }
  }
  for (std::size_t k = 0; k < n_win; ++k) {
    w.du_ext_adm[k] = w.u_pert[k] - m_dev * w.dxdd[k] - d_adm * w.dxd[k];  // eq. 21
    w.du_ext_force[k] = -(w.du_ext_force[k] + m_handle * w.dxdd[k]);
  }
  if (!trial.x_twin_m.empty()) {
    w.dx_true.resize(n_win);
    w.dxd_true.resize(n_win);
    w.dxdd_true.resize(n_win);
    w.du_ext_true.resize(n_win);
    for (std::size_t k = 0; k < n_win; ++k) {
      w.dx_true[k] = trial.x_ref_m[on + k] - trial.x_twin_m[on + k];
      w.dxd_true[k] = trial.xd_ref_m[on + k] - trial.xd_twin_m[on + k];
      w.dxdd_true[k] = trial.xdd_ref_m[on + k] - trial.xdd_twin_m[on + k];
      w.du_ext_true[k] = w.u_pert[k] - m_dev * w.dxdd_true[k] - d_adm * w.dxd_true[k];  // eq. 21, exact signals
    }
  }
  return w;
}

std::vector<double> principal_axis_jerk(const SessionInfo& info, const TrialData& trial, const PipelineSettings& s) {
  const int win = sg_window_for(s, info.sample_rate_hz);
  if (trial.size() < static_cast<std::size_t>(win)) return {};
  const dsp::SavgolFilter jerk_filter(win, s.sg_order, 3, 1.0 / info.sample_rate_hz);
  const auto x2 = axis(trial.x_m, 1);
  std::vector<double> j(x2.size());
  jerk_filter.apply(x2, j);
  return j;
}

}  // namespace manip::estimation
