#include "manip/estimation/tracking_input.hpp"

#include <algorithm>

#include "manip/dsp/savgol.hpp"

namespace manip::estimation {

void add_tracking_input(const SessionInfo& info, const TrialData& encoder, const std::vector<Vec2>& x_ref_aligned,
                        const PipelineSettings& pipe, VariationalWindow& vw, std::span<OeWindow* const> windows) {
  TrialData on_ref = encoder;
  on_ref.x_m = x_ref_aligned;
  const VariationalWindow vr = isolate_variational(info, on_ref, pipe);
  const Mat2 m_adm = info.m_adm_shoulder_kg(), d_adm = info.d_adm_shoulder_nspm();
  const std::size_t n = std::min(vr.size(), vw.size());
  for (std::size_t j = 0; j < n; ++j) vw.du_ext_adm[j] -= m_adm * (vr.dxdd[j] - vw.dxdd[j]) + d_adm * (vr.dxd[j] - vw.dxd[j]);

  // isolate_variational has checked the trial against the SG window's length.
  const std::size_t nt = encoder.size();
  const double dt = 1.0 / info.sample_rate_hz;
  const int win = pipe.sg_window > 0 ? pipe.sg_window : sg_window_for(pipe, info.sample_rate_hz);
  const dsp::SavgolFilter d1(win, pipe.sg_order, 1, dt), d2(win, pipe.sg_order, 2, dt);
  std::vector<double> e(nt), ed(nt), edd(nt);
  std::vector<Vec2> vel(nt), acc(nt);
  for (int a = 0; a < 2; ++a) {
    for (std::size_t k = 0; k < nt; ++k) e[k] = x_ref_aligned[k](a) - encoder.x_m[k](a);
    d1.apply(e, ed);
    d2.apply(e, edd);
    for (std::size_t k = 0; k < nt; ++k) {
      vel[k](a) = ed[k];
      acc[k](a) = edd[k];
    }
  }
  const auto on = static_cast<std::size_t>(encoder.onset_index);
  for (OeWindow* w : windows) {
    if (!w || w->u_n.empty()) continue;
    const std::size_t start = on - static_cast<std::size_t>(w->onset_offset);
    for (std::size_t k = 0; k < w->u_n.size() && start + k < nt; ++k) w->u_n[k] -= m_adm * acc[start + k] + d_adm * vel[start + k];
  }
}

}  // namespace manip::estimation
