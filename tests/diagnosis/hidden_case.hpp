#pragma once
// Hidden-mechanism sessions diagnosed as diagnose_model does (run_planar),
// shared by the manipulandum diagnosis tests: the simulation writes into the
// diagnosis' LogCollector exactly as into a log (truth channels dropped), the
// truth for the checks comes from the generator.
#include <cmath>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "manip/diagnosis/likelihood_stage.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"

#include <catch2/catch.hpp>

namespace manip::diagnosis::testing {

using Eigen::Matrix2d;


struct Outcome {
  Diagnosis dg;
  PemBaseline pem, pem_ext;  // pem_ext: the equation-error extension refitted, amplitude refined by the likelihood
  double alpha = 1.0;
  Matrix2d d_app{Matrix2d::Zero()}, k_app{Matrix2d::Zero()};      // apparent truth (sim/truth.hpp)
  Matrix2d d_intr{Matrix2d::Zero()}, k_intr{Matrix2d::Zero()};    // the person's intrinsic D, K (scaled by the draw)
  sim::HiddenDraw draw;
  int perturbed = 0;
  LikelihoodStage lk;  // the likelihood check (likelihood_stage.hpp)
  Conclusion concl;    // what diagnose_model names, and the corrected D, K
  [[nodiscard]] const LikelihoodCandidate* named_fit(const std::string& id) const {
    for (const auto& c : lk.accepted_fits)
      if (c.id == id) return &c;
    return nullptr;
  }
};

struct Case {
  std::vector<sim::HiddenEffect> effects;
  std::uint64_t hidden_seed = 1;
  int movements = 100;
  int reps = 3;
  sim::NoiseLevel noise = sim::NoiseLevel::realistic;
  int bootstrap = 50;
  int heldout_folds = -1;  // the likelihood check's held-out folds (-1: the engine's 10)
  double pulse_s = 0.0;    // perturbation pulse duration (0: the schema's 150 ms, paper §3.2)
  double pulse_n = 0.0;    // its amplitude (0: the schema's 15 N)
  bool directional = false;  // the library with the direction-dependent reflex (PlanarOptions::directional_reflex)
  std::vector<std::string> mechanisms{};  // the library's mechanisms (PlanarOptions::mechanisms; empty: all)
};

// The case's session as diagnose_model reads it: simulated into the
// diagnosis' LogCollector (truth channels dropped), with what was drawn and
// the person before the draw's impedance scale.
struct Collected {
  std::vector<CollectedSession> ses;
  sim::HiddenDraw draw;
  sim::SessionRunSummary sum;
  sim::LinearHumanParams person;
};

inline Collected collect_case(const Case& c) {
  sim::SessionDesign base;
  base.n_movements = c.movements;
  base.reps_per_angle = c.reps;
  base.session.source = "manip_sim/linear";
  if (c.pulse_s > 0) base.session.perturbation.duration_s = c.pulse_s;
  if (c.pulse_n > 0) base.session.perturbation.amplitude_n = c.pulse_n;
  Collected out;
  out.person = sim::table1_person();
  sim::apply_noise(c.noise, base, out.person);
  auto hs = sim::make_hidden_session(base, out.person, c.effects, c.hidden_seed);
  out.ses.resize(1);
  out.ses[0].name = "hidden";
  LogCollector col(out.ses[0]);
  out.sum = sim::run_session(hs.design, *hs.person, col);
  col.finish();
  out.draw = hs.draw;
  return out;
}

inline Outcome run_case(const Case& c) {
  auto cc = collect_case(c);
  auto& ses = cc.ses;
  const auto& sum = cc.sum;
  const auto& person = cc.person;
  Outcome o;
  o.draw = cc.draw;
  o.perturbed = sum.perturbed;
  if (sum.apparent) {
    o.d_app = sum.apparent->d_nspm;
    o.k_app = sum.apparent->k_npm;
  }
  o.d_intr = person.d_nspm * cc.draw.impedance_scale;
  o.k_intr = person.k_npm * cc.draw.impedance_scale;
  PlanarOptions po;
  if (const char* ord = std::getenv("MANIP_MSTUDY_ORDER")) po.nuisance_order = std::atoi(ord);
  po.directional_reflex = c.directional;
  po.mechanisms = c.mechanisms;
  EngineOptions eo;
  eo.bootstrap = c.bootstrap;
  auto run = run_planar(ses, po, eo, false, c.heldout_folds);
  o.dg = std::move(run.dg);
  o.pem = run.prep.pem;
  if (o.dg.misfit_found()) {
    o.pem_ext = run.prep.refined.fit;
    o.alpha = run.prep.refined.alpha;
  } else {
    o.pem_ext = run.prep.pem;
  }
  o.lk = std::move(run.lk);
  o.concl = std::move(run.concl);
  return o;
}

// One planar trial at 4 kHz for the model-based corrections' checks: the
// paper's admittance (5 kg, 15 N s/m), a 0.25 kg handle, an anisotropic
// M_BSP and a smooth 150 ms pulse on both axes, 601 samples from onset.
inline Dataset one_pulse_trial() {
  Dataset d;
  d.dt_s = 0.00025;
  PlanarTrial p;
  p.m_adm = 5.0 * Matrix2d::Identity();
  p.d_adm = 15.0 * Matrix2d::Identity();
  p.m_handle = 0.25 * Matrix2d::Identity();
  p.m_bsp << 1.8, 0.3, 0.3, 1.2;
  for (std::size_t k = 0; k < 601; ++k) {
    const double t = static_cast<double>(k) * d.dt_s;
    const double s = t < 0.15 ? std::sin(std::numbers::pi * t / 0.15) : 0.0;
    p.u_pert.emplace_back(15.0 * s * s, -6.0 * s * s * s);
  }
  d.planar.push_back(p);
  return d;
}

inline double rel(double est, double truth) { return (est - truth) / std::fabs(truth); }

// The library's mechanism `id` (nullptr: not in it).
inline const Mechanism* find_mechanism(const std::vector<std::unique_ptr<Mechanism>>& lib, const std::string& id) {
  for (const auto& m : lib)
    if (m->id() == id) return m.get();
  return nullptr;
}

// Pooled K and D accuracy in the sense of the issue: the largest relative
// error of the diagonal elements (the off-diagonals are small and their
// relative errors meaningless), D within 20 %, K within 10 %.
inline double worst_diag(const Matrix2d& e, const Matrix2d& t) {
  return std::max(std::fabs(rel(e(0, 0), t(0, 0))), std::fabs(rel(e(1, 1), t(1, 1))));
}

// Pooled accuracy as a matrix: ‖estimate − truth‖_F / ‖truth‖_F (D22 alone is
// small, 5-7 N s/m, and the clean `pem` misses it by up to 25 % on single
// sessions; docs/diagnosis.md).
inline double frob(const Matrix2d& e, const Matrix2d& t) { return (e - t).norm() / t.norm(); }

inline std::string show(const Matrix2d& m) {
  std::ostringstream o;
  o.precision(4);
  o << "[" << m(0, 0) << " " << m(0, 1) << "; " << m(1, 0) << " " << m(1, 1) << "]";
  return o.str();
}


// Hidden feedback the extension separates from the intrinsic part (the
// reflex, the early feedback): the corrected D, K are checked against the
// intrinsic truth, every other mechanism's against the apparent truth.
inline bool separates_feedback(const sim::HiddenEffect& e) {
  return e.mechanism == sim::HiddenMechanism::reflex || e.mechanism == sim::HiddenMechanism::feedback ||
         e.mechanism == sim::HiddenMechanism::reflex_dir;
}

// The main parameter of each mechanism and its true value.
struct MainParam {
  std::string id, param;
  double truth;
};
inline MainParam main_param_of(const sim::HiddenEffect& e, const sim::HiddenDraw& draw, double fs) {
  switch (e.mechanism) {
    case sim::HiddenMechanism::actuation_delay:
      return {"actuation_delay", "delay", static_cast<double>(draw.actuation_delay_cycles) / fs};
    case sim::HiddenMechanism::stage_friction: return {"stage_friction", "F_coulomb", e.magnitude};
    case sim::HiddenMechanism::handle_mass: return {"handle_mass", "handle_extra", e.magnitude};
    case sim::HiddenMechanism::reflex: return {"short_latency_reflex", "delay", draw.reflex_delay_s};
    case sim::HiddenMechanism::feedback: return {"early_feedback", "delay", draw.feedback_delay_s};
    case sim::HiddenMechanism::reflex_dir: return {"directional_reflex", "delay", draw.reflex_delay_s};
    case sim::HiddenMechanism::curl: return {"curl_stiffness", "curl_c", e.magnitude};
    case sim::HiddenMechanism::sensor_lag: return {"force_sensor_lag", "sensor_lag", e.magnitude};
    // Offset and drift have no mechanism (removed by the isolation; docs/diagnosis.md).
    case sim::HiddenMechanism::sensor_offset:
    case sim::HiddenMechanism::sensor_drift: return {"(none)", "", e.magnitude};
  }
  return {};
}

// What diagnose_model concludes (the likelihood check decides, see
// likelihood_stage.hpp): the hidden mechanism named first, its main parameter
// within 20 % (gains: the amplitude at the likelihood optimum; shapes: the
// equation-error grid), a positive held-out likelihood gain, and the
// corrected D, K against the apparent truth (the intrinsic truth for the
// reflex: the extension separates it from the intrinsic part).
// The named mechanism of a hidden effect: its main parameter within 20 % and
// a positive held-out likelihood gain; returns the parameter's value.
inline double check_main_param(const sim::HiddenEffect& e, const Outcome& o) {
  const auto mp = main_param_of(e, o.draw, 4000.0);
  INFO(mp.id);
  const auto* f = o.named_fit(mp.id);
  REQUIRE(f);
  double v = NAN;
  for (const auto& p : f->params)
    if (p.name == mp.param) v = p.est.value;
  INFO(mp.param << " = " << v << " (truth " << mp.truth << ")");
  CHECK(std::fabs(rel(v, mp.truth)) < 0.20);
  REQUIRE(f->heldout_done);
  INFO("held-out likelihood gain " << f->heldout.mean << " +- " << f->heldout.se << " nats per trial");
  CHECK(f->heldout.mean > 0.0);
  return v;
}

// A named candidate's parameter by name (nullptr: it has none of that name).
inline const ParamEstimate* param_named(const LikelihoodCandidate& f, const std::string& name) {
  for (const auto& p : f.params)
    if (p.name == name) return &p;
  return nullptr;
}

// A hidden delayed copy (the reflex, the early feedback) and what its
// extension separates: named first, its delay within 20 % with a positive
// held-out gain, its gain against the intrinsic D, K (`gain_name`) within
// `gain_tol` of the hidden magnitude, the corrected K and D within `k_tol`
// and `d_tol` of the intrinsic truth (relative Frobenius errors).
inline void check_delayed_copy(const Case& c, const Outcome& o, const std::string& gain_name, double gain_tol, double k_tol, double d_tol) {
  const auto& e = c.effects.front();
  const auto id = main_param_of(e, o.draw, 4000.0).id;
  INFO("named: " << (o.concl.named.empty() ? "none" : o.concl.named.front()) << ", hidden " << sim::to_string(e));
  REQUIRE_FALSE(o.concl.named.empty());
  CHECK(o.concl.named.front() == id);
  check_main_param(e, o);
  const auto* f = o.named_fit(id);
  REQUIRE(f);
  const auto* gp = param_named(*f, gain_name);
  const double g = gp ? gp->est.value : NAN;
  INFO(gain_name << " " << g);
  CHECK(std::fabs(rel(g, e.magnitude)) < gain_tol);
  REQUIRE(o.concl.has_corrected);
  const auto& z = o.concl.corrected;
  INFO("K after " << show(z.k) << ", plain pem " << show(o.pem.k) << ", intrinsic " << show(o.k_intr) << "; D after " << show(z.d)
                  << ", intrinsic " << show(o.d_intr));
  CHECK(frob(z.k, o.k_intr) < k_tol);
  CHECK(frob(z.d, o.d_intr) < d_tol);
}

inline void check_named(const Case& c, const Outcome& o) {
  const auto& e = c.effects.front();
  const auto mp = main_param_of(e, o.draw, 4000.0);
  INFO("hidden " << sim::to_string(e) << ", seed " << c.hidden_seed << "; named: " << (o.concl.named.empty() ? "none" : o.concl.named.front())
                 << " (equation error: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << ")");
  REQUIRE(o.lk.available);
  REQUIRE_FALSE(o.concl.named.empty());
  CHECK(o.concl.named.front() == mp.id);
  check_main_param(e, o);
  const bool delayed = separates_feedback(e);
  const Matrix2d kt = delayed ? o.k_intr : o.k_app, dt = delayed ? o.d_intr : o.d_app;
  REQUIRE(o.concl.has_corrected);
  const auto& z = o.concl.corrected;
  INFO("K after " << show(z.k) << " truth " << show(kt) << "; D after " << show(z.d) << " truth " << show(dt));
  CHECK(frob(z.k, kt) < 0.10);
  CHECK(frob(z.d, dt) < 0.20);
  // The mechanism did move the default estimate (else the test proves nothing).
  CHECK(frob(o.pem.k, kt) > 0.10);
}
}  // namespace manip::diagnosis::testing
