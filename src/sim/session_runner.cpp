#include "manip/sim/session_runner.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>

#include "manip/version.hpp"

namespace manip::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

std::uint64_t mix(std::uint64_t a, std::uint64_t b) {  // splitmix64 of a combined key
  std::uint64_t z = a * 0x9E3779B97F4A7C15ull + b + 0x632BE59BD9B4E019ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

void copy2(double dst[2], const Vec2& v) {
  dst[0] = v.x();
  dst[1] = v.y();
}

manip::session_t make_session_message(const SessionDesign& d) {
  manip::session_t s{};
  s.schema_version = manip::session_t::SCHEMA_VERSION;
  s.software_version = manip::kVersion;
  s.source = d.source;
  s.utime_start = 0;
  s.participant_id = d.participant_id;
  s.session_id = d.session_id;
  s.sample_rate_hz = d.sample_rate_hz;
  s.drive_rate_hz = d.sample_rate_hz;
  for (int i = 0; i < 2; ++i) {
    s.m_adm_kg[i] = d.admittance.m_adm_kg(i, i);
    s.d_adm_nspm[i] = d.admittance.d_adm_nspm(i, i);
    s.m_handle_kg[i] = d.admittance.m_handle_kg(i, i);
    s.segment_length_m[i] = d.anthropometrics.length_m[i];
    s.segment_mass_kg[i] = d.anthropometrics.mass_kg[i];
    s.segment_com_m[i] = d.anthropometrics.com_m[i];
    s.segment_inertia_kgm2[i] = d.anthropometrics.inertia_kgm2[i];
  }
  copy2(s.workspace_origin_in_shoulder_m, d.frame.origin_in_shoulder_m);
  s.workspace_to_shoulder_rot_rad = d.frame.rot_rad;
  s.body_mass_kg = 0.0;
  s.body_height_m = 0.0;
  s.pert_duration_s = d.perturbation.duration_s;
  s.pert_amplitude_n = d.perturbation.amplitude_n;
  s.trigger_x2_shoulder_m = d.trigger_x2_shoulder_m;
  s.config_yaml = d.config_yaml;
  return s;
}

// Records one simulated trial segment cycle by cycle.
struct TrialRecord {
  std::vector<manip::state_t> states;
  std::int64_t onset_cycle{-1};
  std::vector<Vec2> x_true;  // shoulder frame, per cycle
};

class Quantizer {
 public:
  explicit Quantizer(double res) : res_(res) {}
  [[nodiscard]] double operator()(double v) const { return res_ > 0.0 ? std::round(v / res_) * res_ : v; }

 private:
  double res_;
};

}  // namespace

std::vector<double> perturbation_schedule(const SessionDesign& d) {
  const int n_pert = static_cast<int>(d.angles_deg.size()) * d.reps_per_angle;
  if (n_pert > d.n_movements)
    throw std::invalid_argument("session design: " + std::to_string(n_pert) + " perturbed trials do not fit in " +
                                std::to_string(d.n_movements) + " movements");
  std::vector<double> sched(static_cast<std::size_t>(d.n_movements), std::numeric_limits<double>::quiet_NaN());
  std::vector<double> angles;
  for (int r = 0; r < d.reps_per_angle; ++r)
    for (double a : d.angles_deg) angles.push_back(a);
  std::mt19937_64 rng(mix(d.seed, 0xA11CE));
  std::shuffle(angles.begin(), angles.end(), rng);
  std::vector<int> idx(static_cast<std::size_t>(d.n_movements));
  for (int i = 0; i < d.n_movements; ++i) idx[static_cast<std::size_t>(i)] = i;
  std::shuffle(idx.begin(), idx.end(), rng);
  std::vector<int> chosen(idx.begin(), idx.begin() + n_pert);
  std::sort(chosen.begin(), chosen.end());
  for (int k = 0; k < n_pert; ++k) sched[static_cast<std::size_t>(chosen[static_cast<std::size_t>(k)])] = angles[static_cast<std::size_t>(k)];
  return sched;
}

SessionRunSummary run_session(const SessionDesign& d, HumanModel& human, logging::SessionHandler& out) {
  if (!(d.sample_rate_hz > 0.0) || d.substeps < 1) throw std::invalid_argument("session design: bad sample rate");
  const double fs = d.sample_rate_hz;
  const double dt = 1.0 / fs;
  const double h = dt / d.substeps;
  const auto sched = perturbation_schedule(d);
  auto* truth_src = dynamic_cast<TruthSource*>(&human);

  SessionRunSummary summary;
  out.on_session(make_session_message(d));

  std::int64_t cycle = 0;
  std::mt19937_64 noise_rng(mix(d.seed, 0xF0C5));
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Quantizer quant(d.encoder_resolution_m);
  const auto utime_of = [&](std::int64_t c) { return static_cast<std::int64_t>(std::llround(c * 1e6 / fs)); };

  // Simulates one trial segment starting at `cycle0`; perturbation applied
  // only if `perturb`. Returns the states; does not emit them.
  const auto simulate = [&](int trial, const ReachSpec& reach, std::uint64_t seed, bool perturb, double angle_rad,
                            std::int64_t cycle0, std::int64_t n_cycles, std::mt19937_64& sensor_rng,
                            Mat2* d_acc, Mat2* k_acc, Mat2* m_acc, int* n_acc, std::int64_t truth_onset) {
    TrialRecord rec;
    rec.states.reserve(static_cast<std::size_t>(n_cycles));
    rec.x_true.reserve(static_cast<std::size_t>(n_cycles));
    human.begin_trial(reach, seed);
    Vec2 u_pert = Vec2::Zero();
    Vec2 xdd = Vec2::Zero();
    Vec2 f_sensor = Vec2::Zero();
    Vec2 prev_meas_ws = d.frame.point_to_workspace(human.hand_position_m());
    prev_meas_ws = Vec2(quant(prev_meas_ws.x()), quant(prev_meas_ws.y()));
    double prev_x2 = human.hand_position_m().y();
    const double dir = (reach.goal_shoulder_m - reach.start_shoulder_m).y() >= 0 ? 1.0 : -1.0;
    for (std::int64_t k = 0; k < n_cycles; ++k) {
      const std::int64_t c = cycle0 + k;
      // Sense.
      const Vec2 x_sh = human.hand_position_m();
      const Vec2 xd_sh = human.hand_velocity_mps();
      Vec2 meas_ws = d.frame.point_to_workspace(x_sh);
      meas_ws = Vec2(quant(meas_ws.x()), quant(meas_ws.y()));
      const Vec2 meas_sh = d.frame.point_to_shoulder(meas_ws);
      // Trigger on the measured position, first crossing towards the goal (§4.2).
      if (perturb && rec.onset_cycle < 0 && trial >= 0) {
        const double x2 = meas_sh.y();
        if (dir * (prev_x2 - d.trigger_x2_shoulder_m) < 0.0 && dir * (x2 - d.trigger_x2_shoulder_m) >= 0.0)
          rec.onset_cycle = c;
        prev_x2 = x2;
      }
      u_pert = (perturb && rec.onset_cycle >= 0)
                   ? d.perturbation.force_n(static_cast<double>(c - rec.onset_cycle) * dt, angle_rad)
                   : Vec2::Zero();
      if (truth_onset >= 0 && c >= truth_onset && static_cast<double>(c - truth_onset) * dt <= d.t_est_s && d_acc) {
        Mat2 m_x;
        Vec2 hh;
        human.endpoint_dynamics(m_x, hh);
        *m_acc += m_x;
        if (truth_src) {
          Mat2 dd, kk;
          truth_src->endpoint_impedance(dd, kk);
          *d_acc += dd;
          *k_acc += kk;
        }
        ++*n_acc;
      }
      // Record the state of this cycle (sensors at the start of the cycle,
      // command applied over the cycle, as in the controller).
      manip::state_t s{};
      s.cycle = c;
      s.utime = utime_of(c);
      s.trial = trial;
      s.phase = static_cast<int8_t>(trial >= 0 ? 1 : 0);
      copy2(s.x_workspace_m, meas_ws);
      copy2(s.xd_workspace_mps, (meas_ws - prev_meas_ws) * fs);
      prev_meas_ws = meas_ws;
      copy2(s.x_ref_workspace_m, d.frame.point_to_workspace(x_sh));
      copy2(s.xd_ref_workspace_mps, d.frame.vector_to_workspace(xd_sh));
      // Step the plant over the cycle with the held perturbation force.
      for (int j = 0; j < d.substeps; ++j) {
        const auto ps = step_ideal_admittance(human, d.admittance, u_pert, h, d.midpoint_plant);
        if (j == 0) {
          xdd = ps.xdd_mps2;
          f_sensor = ps.f_sensor_n;
        }
      }
      copy2(s.xdd_ref_workspace_mps2, d.frame.vector_to_workspace(xdd));
      Vec2 fs_noisy = f_sensor;
      if (d.force_noise_n > 0.0) fs_noisy += d.force_noise_n * Vec2(gauss(sensor_rng), gauss(sensor_rng));
      copy2(s.f_sensor_workspace_n, d.frame.vector_to_workspace(fs_noisy));
      copy2(s.u_pert_workspace_n, d.frame.vector_to_workspace(u_pert));
      s.f_motor_n[0] = s.f_motor_n[1] = 0.0;
      s.mode = 2;
      s.fault_flags = 0;
      rec.states.push_back(s);
      rec.x_true.push_back(x_sh);
    }
    return rec;
  };

  std::uniform_real_distribution<double> jitter(-1.0, 1.0);
  std::mt19937_64 design_rng(mix(d.seed, 0xDE51));
  for (int trial = 0; trial < d.n_movements; ++trial) {
    const double angle_deg = sched[static_cast<std::size_t>(trial)];
    const bool perturbed = !std::isnan(angle_deg);
    const double angle = perturbed ? angle_deg * kDeg : 0.0;
    ReachSpec reach;
    reach.start_shoulder_m = d.start_shoulder_m;
    reach.goal_shoulder_m = d.goal_shoulder_m;
    reach.t_start_s = d.rest_before_s;
    reach.duration_s = d.reach_duration_s + d.reach_duration_jitter_s * jitter(design_rng);
    reach.lateral_bow_m = d.lateral_bow_std_m * gauss(design_rng);
    const std::uint64_t seed = mix(d.seed, static_cast<std::uint64_t>(trial) + 1);
    const auto n_cycles = static_cast<std::int64_t>(std::ceil((reach.t_start_s + reach.duration_s + d.rest_after_s) * fs));
    std::mt19937_64 sensor_rng(mix(seed, 0x5E45));

    manip::trial_event_t ev{};
    ev.trial = trial;
    ev.perturbed = perturbed;
    copy2(ev.start_shoulder_m, reach.start_shoulder_m);
    copy2(ev.goal_shoulder_m, reach.goal_shoulder_m);
    ev.pert_angle_rad = angle;
    ev.pert_amplitude_n = perturbed ? d.perturbation.amplitude_n : 0.0;
    ev.pert_duration_s = perturbed ? d.perturbation.duration_s : 0.0;
    ev.kind = manip::trial_event_t::START;
    ev.cycle = cycle;
    ev.utime = utime_of(cycle);
    out.on_trial_event(ev);

    // Perturbed run first: its onset is where the unperturbed twin (same seed,
    // same sensor noise, identical until onset) accumulates the truth.
    auto rec = simulate(trial, reach, seed, perturbed, angle, cycle, n_cycles, sensor_rng, nullptr, nullptr, nullptr,
                        nullptr, -1);
    TrialRecord twin;
    Mat2 d_acc = Mat2::Zero(), k_acc = Mat2::Zero(), m_acc = Mat2::Zero();
    int n_acc = 0;
    if (perturbed) {
      std::mt19937_64 twin_sensor_rng(mix(seed, 0x5E45));
      twin = simulate(trial, reach, seed, false, angle, cycle, n_cycles, twin_sensor_rng, &d_acc, &k_acc, &m_acc, &n_acc,
                      rec.onset_cycle);
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
      if (n_acc > 0) {
        manip::impedance_truth_t t{};
        t.trial = trial;
        t.t_est_s = d.t_est_s;
        const Mat2 mm = m_acc / n_acc, dd = d_acc / n_acc, kk = k_acc / n_acc;
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
      auto ret = simulate(-1, back, mix(seed, 0xBAC0), false, 0.0, cycle, n_ret, sensor_rng, nullptr, nullptr, nullptr,
                          nullptr, -1);
      for (const auto& s : ret.states) out.on_state(s);
      cycle += n_ret;
    }
  }
  summary.cycles = cycle;
  return summary;
}

}  // namespace manip::sim
