#include "manip/sim/session_runner.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "manip/common/rng.hpp"
#include "manip/control/trigger.hpp"
#include "manip/model/arm.hpp"
#include "manip/schema/codes.hpp"
#include "manip/sim/truth.hpp"
#include "manip/version.hpp"

namespace manip::sim {
namespace {

// Independent streams from one session seed: the first PortableRng draw of a
// combined key, so each consumer (reach design, sensor noise, per-trial human
// noise) has its own generator and a draw added in one does not shift the others.
std::uint64_t mix(std::uint64_t a, std::uint64_t b) { return PortableRng(a * 0x9E3779B97F4A7C15ull + b).next(); }

void copy2(double dst[2], const Vec2& v) {
  dst[0] = v.x();
  dst[1] = v.y();
}

// One simulated trial segment, cycle by cycle.
struct TrialRecord {
  std::vector<manip::state_t> states;
  std::int64_t onset_cycle{-1};
  std::vector<Vec2> x_true;  // shoulder frame, per cycle
  // Exact velocity, acceleration (first substep, consistent with x, xd at the
  // cycle's start) and perturbation force: the apparent truth's signals.
  std::vector<Vec2> xd_true, xdd_true, u_pert;
};

class Quantizer {
 public:
  explicit Quantizer(double res) : res_(res) {}
  [[nodiscard]] double operator()(double v) const { return res_ > 0.0 ? std::round(v / res_) * res_ : v; }

 private:
  double res_;
};

// Truth accumulated over [onset, onset + T_est] of the unperturbed twin.
struct TruthAccumulator {
  std::int64_t onset{-1};
  Mat2 m{Mat2::Zero()}, d{Mat2::Zero()}, k{Mat2::Zero()};
  int n{0};
};

void check_design(const SessionDesign& d) {
  if (auto why = d.session.invalid_reason()) throw std::invalid_argument("session design: " + *why);
  if (d.substeps < 1) throw std::invalid_argument("session design: substeps must be >= 1");
  if (d.actuation_delay_cycles < 0) throw std::invalid_argument("session design: negative actuation delay");
  if (!(d.hidden_handle_extra_kg >= 0.0) || !(d.hidden_stage_friction_n >= 0.0))
    throw std::invalid_argument("session design: hidden handle mass and stage friction must be >= 0");
  if (!(d.hidden_sensor_lag_s >= 0.0) || !std::isfinite(d.hidden_sensor_lag_s) || !std::isfinite(d.hidden_sensor_offset_n) ||
      !std::isfinite(d.hidden_sensor_drift_nps))
    throw std::invalid_argument("session design: hidden force-sensor lag must be >= 0, offset and drift finite");
  if (d.n_movements < 0) throw std::invalid_argument("session design: negative number of movements");
  const int n_pert = static_cast<int>(d.angles_deg.size()) * d.reps_per_angle;
  if (n_pert > d.n_movements)
    throw std::invalid_argument("session design: " + std::to_string(n_pert) + " perturbed trials do not fit in " +
                                std::to_string(d.n_movements) + " movements");
}

}  // namespace

schema::SessionDescription default_sim_session() {
  schema::SessionDescription s;
  s.software_version = manip::kVersion;
  s.source = "manip_sim";
  s.participant_id = "sim";
  s.session_id = "sim-0";
  s.drive_rate_hz = s.sample_rate_hz;
  return s;
}

std::vector<control::TrialSpec> perturbation_schedule(const SessionDesign& d) {
  check_design(d);
  const int n_pert = static_cast<int>(d.angles_deg.size()) * d.reps_per_angle;
  return control::make_schedule(d.n_movements, d.angles_deg, d.reps_per_angle, n_pert, d.seed);
}

SessionRunSummary run_session(const SessionDesign& d, HumanModel& human, logging::SessionHandler& out) {
  const auto sched = perturbation_schedule(d);
  const double fs = d.session.sample_rate_hz;
  const double dt = 1.0 / fs;
  const double h = dt / d.substeps;
  const PlantParams plant = plant_params(d.session);
  // The plant as built (hidden handle mass included): what the apparent truth
  // must use so that it stays the person's (truth.hpp).
  PlantParams plant_true = plant;
  plant_true.m_handle_kg += d.hidden_handle_extra_kg * Mat2::Identity();
  const auto stage_friction = [&](const Vec2& xd_shoulder) -> Vec2 {
    if (d.hidden_stage_friction_n <= 0.0) return Vec2::Zero();
    constexpr double kSmoothingMps = 1e-3;  // keeps the explicit step from chattering at rest
    const Vec2 v = d.session.frame.vector_to_workspace(xd_shoulder);
    return d.session.frame.vector_to_shoulder(Vec2(-d.hidden_stage_friction_n * std::tanh(v.x() / kSmoothingMps),
                                                   -d.hidden_stage_friction_n * std::tanh(v.y() / kSmoothingMps)));
  };
  // Hidden force-sensor bias (offset + drift over the session), shoulder frame,
  // at time t_s of the session (the same in a trial and its twin).
  const auto sensor_bias = [&](double t_s) -> Vec2 {
    const double b = d.hidden_sensor_offset_n + d.hidden_sensor_drift_nps * t_s;
    return b == 0.0 ? Vec2::Zero() : Vec2(d.session.frame.vector_to_shoulder(Vec2(b, b)));
  };
  const bool sensor_lag = d.hidden_sensor_lag_s > 0.0;
  const double lag_alpha = sensor_lag ? 1.0 - std::exp(-h / d.hidden_sensor_lag_s) : 1.0;
  const PerturbationProfile profile = d.perturbation();
  const auto& frame = d.session.frame;
  auto* truth_src = dynamic_cast<TruthSource*>(&human);

  SessionRunSummary summary;
  out.on_session(schema::to_message(d.session));

  std::int64_t cycle = 0;
  const Quantizer quant(d.encoder_resolution_m);
  const auto utime_of = [&](std::int64_t c) { return static_cast<std::int64_t>(std::llround(c * 1e6 / fs)); };
  control::PerturbationTrigger trigger(d.session.perturbation.trigger_x2_shoulder_m, fs);

  // Simulates one trial segment starting at `cycle0` (trial -1: the return
  // between trials). A perturbed run arms the controller's trigger; the twin
  // (truth != nullptr) is never perturbed and accumulates the truth from the
  // perturbed run's onset. Returns the states; does not emit them.
  const auto simulate = [&](int trial, const ReachSpec& reach, std::uint64_t seed, bool perturb, double angle_rad,
                            std::int64_t cycle0, std::int64_t n_cycles, PortableRng& sensor_rng,
                            TruthAccumulator* truth) {
    TrialRecord rec;
    rec.states.reserve(static_cast<std::size_t>(n_cycles));
    rec.x_true.reserve(static_cast<std::size_t>(n_cycles));
    if (trial >= 0) {
      rec.xd_true.reserve(static_cast<std::size_t>(n_cycles));
      rec.xdd_true.reserve(static_cast<std::size_t>(n_cycles));
      rec.u_pert.reserve(static_cast<std::size_t>(n_cycles));
    }
    human.begin_trial(reach, seed);
    if (perturb)
      trigger.arm(angle_rad, profile, (reach.goal_shoulder_m - reach.start_shoulder_m).y() >= 0 ? 1.0 : -1.0);
    else
      trigger.clear();
    trigger.forget_previous();
    Vec2 xdd = Vec2::Zero();
    Vec2 f_sensor = Vec2::Zero();
    Vec2 f_lag = Vec2::Zero();  // the lagged sensor's filter state (hidden sensor_lag), shoulder frame
    Vec2 prev_meas_ws = frame.point_to_workspace(human.hand_position_m());
    prev_meas_ws = Vec2(quant(prev_meas_ws.x()), quant(prev_meas_ws.y()));
    for (std::int64_t k = 0; k < n_cycles; ++k) {
      const std::int64_t c = cycle0 + k;
      // Sense: encoder position, its backward difference as the velocity (what
      // the controller sees), both also in the shoulder frame.
      const Vec2 x_sh = human.hand_position_m();
      const Vec2 xd_sh = human.hand_velocity_mps();
      Vec2 meas_ws = frame.point_to_workspace(x_sh);
      meas_ws = Vec2(quant(meas_ws.x()), quant(meas_ws.y()));
      const Vec2 meas_xd_ws = (meas_ws - prev_meas_ws) * fs;
      const Vec2 meas_sh = frame.point_to_shoulder(meas_ws);
      const Vec2 meas_xd_sh = frame.vector_to_shoulder(meas_xd_ws);
      // The controller's trigger on the measured position and velocity (§4.2).
      if (trial >= 0 && trigger.update(c, meas_sh.y(), meas_xd_sh.y())) rec.onset_cycle = c;
      const bool pert_active = trial >= 0 && trigger.active(c);
      const Vec2 u_pert = trigger.force_shoulder_n(c);
      if (truth && truth->onset >= 0 && c >= truth->onset && static_cast<double>(c - truth->onset) * dt <= d.t_est_s) {
        Mat2 m_x;
        Vec2 hh;
        human.endpoint_dynamics(m_x, hh);
        truth->m += m_x;
        if (truth_src) {
          Mat2 dd, kk;
          truth_src->endpoint_impedance(dd, kk);
          truth->d += dd;
          truth->k += kk;
        }
        ++truth->n;
      }
      // Record the state of this cycle (sensors at the start of the cycle,
      // command applied over the cycle, as in the controller), with the
      // documented codes (docs/schema-controller.md): RETURN between trials;
      // in a trial PERTURBATION for T_pert from onset, GOAL_HOLD while resting
      // in the goal (control::Protocol::in_goal), else REACH.
      manip::state_t s{};
      s.cycle = c;
      s.utime = utime_of(c);
      s.trial = trial;
      // The END cycle (the trial's last) carries the index and RETURN, as the
      // controller logs it.
      schema::Phase phase = schema::Phase::kReturn;
      if (trial >= 0 && k + 1 < n_cycles) {
        const bool in_goal = (meas_sh - reach.goal_shoulder_m).norm() <= d.target_radius_m &&
                             meas_xd_sh.norm() <= d.rest_speed_mps;
        phase = pert_active ? schema::Phase::kPerturbation : in_goal ? schema::Phase::kGoalHold : schema::Phase::kReach;
      }
      s.phase = static_cast<std::int8_t>(phase);
      s.mode = static_cast<std::int8_t>(schema::Mode::kRunning);
      copy2(s.x_workspace_m, meas_ws);
      copy2(s.xd_workspace_mps, meas_xd_ws);
      prev_meas_ws = meas_ws;
      copy2(s.x_ref_workspace_m, frame.point_to_workspace(x_sh));
      copy2(s.xd_ref_workspace_mps, frame.vector_to_workspace(xd_sh));
      // Step the plant over the cycle with the held perturbation force (the
      // commanded one, or with a hidden actuation delay the one commanded
      // actuation_delay_cycles earlier; the log keeps the commanded force).
      const Vec2 u_applied =
          d.actuation_delay_cycles > 0 ? trigger.force_shoulder_n(c - d.actuation_delay_cycles) : u_pert;
      // The force sensor (hidden sensor_lag/offset/drift): the admittance renders
      // from the reading f_r = LP_tau(f) + bias, the log records f_r; f is the
      // force the sensor bears (hand on handle minus the handle's inertia).
      // Without lag the reading is algebraic and the bias acts like a force on
      // the admittance: step_ideal_admittance with u + bias, f = its f_sensor.
      // With lag the admittance's acceleration follows the reading alone
      // (M_adm ẍ + D_adm ẋ = f_r + u), f = h − (M_x + M_handle) ẍ, and the
      // filter state steps exactly, f_lag += (1 − e^(−h/tau)) (f − f_lag).
      // f_extra0 gets f_r − f so that eq. 21 on the exact signals gives the
      // person's true Δu_ext (the apparent truth stays the person's).
      Vec2 f_extra0 = u_applied;
      for (int j = 0; j < d.substeps; ++j) {
        const Vec2 f_fric = stage_friction(human.hand_velocity_mps());
        const Vec2 bias = sensor_bias((static_cast<double>(c) + static_cast<double>(j) / d.substeps) * dt);
        if (!sensor_lag) {
          const auto ps = step_ideal_admittance(human, plant_true, u_applied + f_fric + bias, h, d.midpoint_plant);
          if (j == 0) {
            f_extra0 = u_applied + f_fric + bias;
            xdd = ps.xdd_mps2;
            f_sensor = ps.f_sensor_n + bias;
          }
          continue;
        }
        Mat2 m_x;
        Vec2 hh;
        if (d.midpoint_plant)
          human.endpoint_dynamics_for_step(h, m_x, hh);
        else
          human.endpoint_dynamics(m_x, hh);
        Mat2 m_adm = plant_true.m_adm_kg;
        if (d.midpoint_plant) m_adm += (0.5 * h) * plant_true.d_adm_nspm;
        const Vec2 f_read = f_lag + bias;
        const Vec2 a = m_adm.ldlt().solve(Vec2(f_read + u_applied + f_fric - plant_true.d_adm_nspm * human.hand_velocity_mps()));
        const Vec2 f_true = hh - (m_x + plant_true.m_handle_kg) * a;
        if (j == 0) {
          f_extra0 = u_applied + f_fric + (f_read - f_true);
          xdd = a;
          f_sensor = f_read;
        }
        human.advance(h, a);
        f_lag += lag_alpha * (f_true - f_lag);
      }
      copy2(s.xdd_ref_workspace_mps2, frame.vector_to_workspace(xdd));
      Vec2 fs_noisy = f_sensor;
      if (d.force_noise_n > 0.0) {
        const double n1 = sensor_rng.normal();
        const double n2 = sensor_rng.normal();
        fs_noisy += d.force_noise_n * Vec2(n1, n2);
      }
      copy2(s.f_sensor_workspace_n, frame.vector_to_workspace(fs_noisy));
      copy2(s.u_pert_workspace_n, frame.vector_to_workspace(u_pert));
      s.f_motor_n[0] = s.f_motor_n[1] = 0.0;
      s.fault_flags = 0;
      rec.states.push_back(s);
      rec.x_true.push_back(x_sh);
      if (trial >= 0) {
        rec.xd_true.push_back(xd_sh);
        rec.xdd_true.push_back(xdd);
        rec.u_pert.push_back(f_extra0);  // all non-admittance force the plant felt: the apparent truth is the person's
      }
    }
    trigger.clear();
    return rec;
  };

  // Apparent truth (truth.hpp): exact Δ signals of each perturbed trial over
  // [onset, onset + T_est], Δu_ext by eq. 21, M_BSP as the estimator takes it
  // (eq. 16 at the onset position); fitted once over the session at the end.
  const TwoLinkArm arm(d.session.anthropometrics);
  std::vector<VariationalSamples> apparent_windows;
  const auto add_apparent_window = [&](const TrialRecord& pert, const TrialRecord& tw, std::int64_t cycle0) {
    if (pert.onset_cycle < cycle0) return;
    const auto k0 = static_cast<std::size_t>(pert.onset_cycle - cycle0);
    if (k0 >= pert.x_true.size() || tw.xd_true.size() != pert.xd_true.size()) return;
    const auto m_bsp = arm.endpoint_inertia_at(pert.x_true[k0]);
    if (!m_bsp) return;
    VariationalSamples w;
    w.m_bsp_kg = *m_bsp;
    for (std::size_t k = k0; k < pert.x_true.size() && static_cast<double>(k - k0) * dt <= d.t_est_s; ++k) {
      w.dx_m.push_back(pert.x_true[k] - tw.x_true[k]);
      w.dxd_mps.push_back(pert.xd_true[k] - tw.xd_true[k]);
      w.dxdd_mps2.push_back(pert.xdd_true[k] - tw.xdd_true[k]);
      w.du_ext_n.push_back(
          variational_external_force(plant_true, pert.u_pert[k] - tw.u_pert[k], w.dxd_mps.back(), w.dxdd_mps2.back()));
    }
    apparent_windows.push_back(std::move(w));
  };

  int last_perturbed = -1;
  for (int i = 0; i < d.n_movements; ++i)
    if (sched[static_cast<std::size_t>(i)].perturbed) last_perturbed = i;
  PortableRng design_rng(mix(d.seed, 0xDE51));
  for (int trial = 0; trial < d.n_movements; ++trial) {
    const auto& spec = sched[static_cast<std::size_t>(trial)];
    const bool perturbed = spec.perturbed;
    const double angle = perturbed ? spec.angle_rad : 0.0;
    ReachSpec reach;
    reach.start_shoulder_m = d.start_shoulder_m;
    reach.goal_shoulder_m = d.goal_shoulder_m;
    reach.t_start_s = d.rest_before_s;
    reach.duration_s = d.reach_duration_s + d.reach_duration_jitter_s * design_rng.uniform(-1.0, 1.0);
    reach.lateral_bow_m = d.lateral_bow_std_m * design_rng.normal();
    const std::uint64_t seed = mix(d.seed, static_cast<std::uint64_t>(trial) + 1);
    const auto n_cycles = static_cast<std::int64_t>(std::ceil((reach.t_start_s + reach.duration_s + d.rest_after_s) * fs));
    PortableRng sensor_rng(mix(seed, 0x5E45));

    manip::trial_event_t ev{};
    ev.trial = trial;
    ev.perturbed = perturbed;
    copy2(ev.start_shoulder_m, reach.start_shoulder_m);
    copy2(ev.goal_shoulder_m, reach.goal_shoulder_m);
    ev.pert_angle_rad = angle;
    ev.pert_amplitude_n = perturbed ? profile.amplitude_n : 0.0;
    ev.pert_duration_s = perturbed ? profile.duration_s : 0.0;
    ev.kind = manip::trial_event_t::START;
    ev.cycle = cycle;
    ev.utime = utime_of(cycle);
    out.on_trial_event(ev);

    // Perturbed run first: its onset is where the unperturbed twin (same seed,
    // same sensor noise, identical until onset) accumulates the truth.
    auto rec = simulate(trial, reach, seed, perturbed, angle, cycle, n_cycles, sensor_rng, nullptr);
    TrialRecord twin;
    TruthAccumulator acc;
    if (perturbed) {
      PortableRng twin_sensor_rng(mix(seed, 0x5E45));
      acc.onset = rec.onset_cycle;
      twin = simulate(trial, reach, seed, false, angle, cycle, n_cycles, twin_sensor_rng, &acc);
    }
    for (std::size_t k = 0; k < rec.states.size(); ++k) {
      if (perturbed && static_cast<std::int64_t>(k) + cycle == rec.onset_cycle) {
        ev.kind = manip::trial_event_t::ONSET;
        ev.cycle = rec.onset_cycle;
        ev.utime = utime_of(rec.onset_cycle);
        out.on_trial_event(ev);
      }
      out.on_state(rec.states[k]);
    }
    if (perturbed && d.write_twins)
      for (const auto& s : twin.states) out.on_truth_state(s);
    if (perturbed && rec.onset_cycle >= 0) {
      ++summary.onsets;
      double m1 = 0.0, m2 = 0.0;
      for (std::size_t k = 0; k < rec.x_true.size(); ++k) {
        const auto c = static_cast<std::int64_t>(k) + cycle;
        if (c < rec.onset_cycle || static_cast<double>(c - rec.onset_cycle) * dt > d.t_est_s) continue;
        const Vec2 dx = rec.x_true[k] - twin.x_true[k];
        m1 = std::max(m1, std::abs(dx.x()));
        m2 = std::max(m2, std::abs(dx.y()));
      }
      summary.max_dev_x1_m.push_back(m1);
      summary.max_dev_x2_m.push_back(m2);
      if (d.write_apparent_truth) add_apparent_window(rec, twin, cycle);
      if (acc.n > 0) {
        manip::impedance_truth_t t{};
        t.trial = trial;
        t.t_est_s = d.t_est_s;
        const Mat2 mm = acc.m / acc.n, dd = acc.d / acc.n, kk = acc.k / acc.n;
        for (int i = 0; i < 2; ++i)
          for (int j = 0; j < 2; ++j) {
            t.m_kg[2 * i + j] = mm(i, j);
            t.d_nspm[2 * i + j] = dd(i, j);
            t.k_npm[2 * i + j] = kk(i, j);
          }
        t.model = truth_src ? truth_src->truth_model() : "unknown";
        out.on_truth_impedance(t);
      }
    }
    // One apparent truth for the session, once the last perturbed trial is
    // in (before its END event, so a log still ends with a trial event):
    // trial -1, so readers that attach a truth to a trial keep the intrinsic one.
    if (d.write_apparent_truth && trial == last_perturbed) {
      summary.apparent = fit_apparent_impedance(apparent_windows);
      if (summary.apparent) {
        manip::impedance_truth_t t{};
        t.trial = -1;
        t.t_est_s = d.t_est_s;
        for (int i = 0; i < 2; ++i)
          for (int j = 0; j < 2; ++j) {
            t.m_kg[2 * i + j] = summary.apparent->m_bsp_kg(i, j);
            t.d_nspm[2 * i + j] = summary.apparent->d_nspm(i, j);
            t.k_npm[2 * i + j] = summary.apparent->k_npm(i, j);
          }
        t.model = kApparentTruthModel;
        out.on_truth_impedance(t);
      }
    }
    cycle += n_cycles;
    ev.kind = manip::trial_event_t::END;
    ev.cycle = cycle - 1;
    ev.utime = utime_of(cycle - 1);
    out.on_trial_event(ev);
    ++summary.trials;
    if (perturbed) ++summary.perturbed;

    // Return to the start between trials (trial = -1), perturbations off.
    if (trial + 1 < d.n_movements && d.return_s > 0.0) {
      ReachSpec back;
      back.start_shoulder_m = human.hand_position_m();
      back.goal_shoulder_m = d.start_shoulder_m;
      back.t_start_s = 0.0;
      back.duration_s = d.return_s * 0.8;
      const auto n_ret = static_cast<std::int64_t>(std::ceil(d.return_s * fs));
      auto ret = simulate(-1, back, mix(seed, 0xBAC0), false, 0.0, cycle, n_ret, sensor_rng, nullptr);
      for (const auto& s : ret.states) out.on_state(s);
      cycle += n_ret;
    }
  }
  summary.cycles = cycle;
  return summary;
}

}  // namespace manip::sim
