#include "manip/estimation/pem.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <unsupported/Eigen/MatrixFunctions>

namespace manip::estimation {
namespace {

constexpr int kNx = 10;  // disturbance model: p(2), v(2), s(2), ṡ(2), n(2)
using Mat10 = Eigen::Matrix<double, kNx, kNx>;
using Mat10x2 = Eigen::Matrix<double, kNx, 2>;
using Vec10 = Eigen::Matrix<double, kNx, 1>;

// The filter runs in scaled units so that the covariance stays well
// conditioned (position variance ~1e-13 m² next to drive variance ~1e3 N²):
// p [µm], v [mm/s], s, n [N], ṡ [N/s].
const Vec10 kScale = (Vec10() << 1e6, 1e6, 1e3, 1e3, 1, 1, 1, 1, 1, 1).finished();

// Bounds on the log noise parameters (SI; r in µm²): wide, only to keep the
// optimiser away from degenerate corners (σ_n -> 0, τ -> 0).
constexpr double kLogLo[4] = {-9.2, -9.2, -5.3, -4.6};   // q 1e-4, σ 1e-4 N, τ 5 ms, r 0.01 µm² (0.1 µm rms)
constexpr double kLogHi[4] = {23.0, 2.3, 0.0, 9.2};      // q 1e10, σ 10 N, τ 1 s, r 1e4 µm²

// Φ's last six rows carry the disturbance's own states, which the arm does
// not drive: s integrates ṡ, ṡ is a random walk, n decays on its own (the
// continuous A is zero there except A_sṡ = I and A_nn = −I/τ). The matrix
// exponential keeps those zeros exactly (checked on each Φ: `tail_sparse`),
// so the filter multiplies by the top four rows in full and by six scalars
// below them instead of the whole 10 × 10 matrix: the same sums without
// their terms in exact zeros (equal up to the order of rounding), at about
// half the multiplications in the innovations and 60 % in the time update.
struct Discrete {
  Mat10 phi;
  bool tail_sparse{false};
  Mat10x2 gam;
  Mat10 q;
  double r{0};
};

// Φ's rows 4-9 nonzero only at (4,4) (4,6) (5,5) (5,7) and on the diagonal.
bool tail_is_sparse(const Mat10& phi) {
  for (int r = 4; r < kNx; ++r)
    for (int c = 0; c < kNx; ++c) {
      const bool allowed = c == r || (r < 6 && c == r + 2);
      if (!allowed && phi(r, c) != 0.0) return false;
    }
  return true;
}

// Φ v, using the sparse tail when there is one.
Vec10 phi_times(const Discrete& m, const Vec10& v) {
  if (!m.tail_sparse) return m.phi.lazyProduct(v);
  Vec10 out;
  out.head<4>().noalias() = m.phi.topRows<4>().lazyProduct(v);
  out(4) = m.phi(4, 4) * v(4) + m.phi(4, 6) * v(6);
  out(5) = m.phi(5, 5) * v(5) + m.phi(5, 7) * v(7);
  for (int i = 6; i < kNx; ++i) out(i) = m.phi(i, i) * v(i);
  return out;
}

Mat2 unpack_d(const Eigen::VectorXd& p) { return (Mat2() << p(0), p(1), p(2), p(3)).finished(); }
Mat2 unpack_k(const Eigen::VectorXd& p) { return (Mat2() << p(4), p(5), p(5), p(6)).finished(); }

// Parameter vector: D (4), K (3) of the perturbation response; for the
// Box-Jenkins structure the disturbance's own damping (full, 4) and stiffness
// (symmetric, 3); then log q_s, log σ_n, log τ, log r (r in µm²).
struct Layout {
  bool bj{true};
  [[nodiscard]] int n_dyn() const { return bj ? 7 : 0; }
  [[nodiscard]] int log0() const { return 7 + n_dyn(); }
  [[nodiscard]] int size() const { return log0() + 4; }
};

// The disturbance model's arm: in the ARMAX-like structure the same D, K as
// the perturbation response; in Box-Jenkins its own D_v, K_v.
void disturbance_arm(const Layout& l, const Eigen::VectorXd& p, Mat2& d, Mat2& k) {
  if (l.bj) {
    d << p(7), p(8), p(9), p(10);
    k << p(11), p(12), p(12), p(13);
  } else {
    d = unpack_d(p);
    k = unpack_k(p);
  }
}

Discrete discretise(const Layout& l, const Eigen::VectorXd& p, const Mat2& m_tot, const Mat2& d_adm, double h) {
  const Mat2 minv = m_tot.inverse();
  const int L = l.log0();
  const double q_s = std::exp(p(L)), sigma = std::exp(p(L + 1)), tau = std::exp(p(L + 2));
  Mat2 dv, kv;
  disturbance_arm(l, p, dv, kv);
  Mat10 a = Mat10::Zero();
  a.block<2, 2>(0, 2) = Mat2::Identity();
  a.block<2, 2>(2, 0) = -minv * kv;
  a.block<2, 2>(2, 2) = -minv * (dv + d_adm);
  a.block<2, 2>(2, 4) = minv;  // smooth drive s
  a.block<2, 2>(2, 8) = minv;  // motor noise n, same point of action as u_pert
  a.block<2, 2>(4, 6) = Mat2::Identity();
  a.block<2, 2>(8, 8) = -Mat2::Identity() / tau;
  Mat10x2 b = Mat10x2::Zero();
  b.block<2, 2>(2, 0) = minv;
  Mat10 qc = Mat10::Zero();
  qc.block<2, 2>(6, 6) = Mat2::Identity() * q_s;
  qc.block<2, 2>(8, 8) = Mat2::Identity() * (2.0 * sigma * sigma / tau);  // stationary variance σ²
  // Scaled coordinates z_s = T z.
  const Mat10 as = kScale.asDiagonal() * a * kScale.cwiseInverse().asDiagonal();
  const Mat10x2 bs = kScale.asDiagonal() * b;
  const Mat10 qs = kScale.asDiagonal() * qc * kScale.asDiagonal();
  // Van Loan (1978): Φ and the exact discrete process-noise covariance.
  Eigen::Matrix<double, 2 * kNx, 2 * kNx> vl = Eigen::Matrix<double, 2 * kNx, 2 * kNx>::Zero();
  vl.topLeftCorner<kNx, kNx>() = -as * h;
  vl.topRightCorner<kNx, kNx>() = qs * h;
  vl.bottomRightCorner<kNx, kNx>() = as.transpose() * h;
  const Eigen::Matrix<double, 2 * kNx, 2 * kNx> ev = vl.exp();
  Discrete d;
  d.phi = ev.bottomRightCorner<kNx, kNx>().transpose();
  d.tail_sparse = tail_is_sparse(d.phi);
  d.q = d.phi * ev.topRightCorner<kNx, kNx>();
  d.q = 0.5 * (d.q + d.q.transpose()).eval();
  // Zero-order hold of the perturbation force, as logged (held per cycle).
  Eigen::Matrix<double, kNx + 2, kNx + 2> zb = Eigen::Matrix<double, kNx + 2, kNx + 2>::Zero();
  zb.topLeftCorner<kNx, kNx>() = as * h;
  zb.topRightCorner<kNx, 2>() = bs * h;
  d.gam = zb.exp().topRightCorner<kNx, 2>();
  d.r = std::exp(p(L + 3));
  return d;
}

// Kalman gains, innovation covariances: data independent, shared by all trials.
struct Gains {
  std::vector<Mat10x2> k;
  std::vector<Mat2> s, l_inv;
  std::vector<double> log_det;
};

Gains riccati(const Discrete& m, std::size_t n, double sigma_n) {
  Gains g;
  g.k.resize(n);
  g.s.resize(n);
  g.l_inv.resize(n);
  g.log_det.resize(n);
  // Diffuse-enough prior for the states the data pin down within a few
  // samples; the motor noise starts from its stationary distribution.
  Vec10 p0;
  p0 << 1.0, 1.0, 500.0 * 500.0, 500.0 * 500.0, 30.0 * 30.0, 30.0 * 30.0, 300.0 * 300.0, 300.0 * 300.0,
      sigma_n * sigma_n, sigma_n * sigma_n;
  Mat10 p = p0.asDiagonal();
  for (std::size_t k = 0; k < n; ++k) {
    // Once the gain has settled (to 1e-12 relative), the rest of the window
    // reuses it: the same filter to rounding, at a fraction of the cost.
    if (k >= 2 && (g.k[k - 1] - g.k[k - 2]).cwiseAbs().maxCoeff() <= 1e-12 * g.k[k - 1].cwiseAbs().maxCoeff() &&
        (g.s[k - 1] - g.s[k - 2]).cwiseAbs().maxCoeff() <= 1e-12 * g.s[k - 1].cwiseAbs().maxCoeff()) {
      for (std::size_t j = k; j < n; ++j) {
        g.k[j] = g.k[k - 1];
        g.s[j] = g.s[k - 1];
        g.l_inv[j] = g.l_inv[k - 1];
        g.log_det[j] = g.log_det[k - 1];
      }
      break;
    }
    const Mat2 s = p.topLeftCorner<2, 2>() + Mat2::Identity() * m.r;
    const Eigen::LLT<Mat2> llt(s);
    const Mat2 l = llt.matrixL();
    const Mat2 sinv = llt.solve(Mat2::Identity());
    const Mat10x2 kk = p.leftCols<2>().lazyProduct(sinv);
    // Joseph form (I − KH) P (I − KH)ᵀ + K R Kᵀ: a sum of positive
    // semidefinite terms, which the filter needs when σ_n and r sit at their
    // floors (the expanded P − K S Kᵀ loses definiteness there). With
    // H = [I₂ 0] both factors are rank-2 updates, (I − KH) P = P − K P₁₂ and
    // A (I − KH)ᵀ = A − A₁₂ Kᵀ (P₁₂: P's first two rows, A₁₂: A's first two
    // columns): the same two products without the multiplications by the
    // identity's zeros, 400 multiply-adds instead of 2 000. Fixed-size
    // products unrolled (lazyProduct): Eigen's blocked kernel costs more in
    // packing than it saves at this size.
    Mat10 a = p;
    a.noalias() -= kk.lazyProduct(p.topRows<2>());
    p = a;
    p.noalias() -= a.leftCols<2>().lazyProduct(kk.transpose());
    p.noalias() += (m.r * kk).lazyProduct(kk.transpose());
    g.k[k] = kk;
    g.s[k] = s;
    g.l_inv[k] = l.inverse();
    g.log_det[k] = 2.0 * (std::log(l(0, 0)) + std::log(l(1, 1)));
    // Time update Φ P Φᵀ + Q: symmetric, so only its lower triangle is
    // kept and then mirrored (which also keeps P exactly symmetric). With
    // Φ's sparse tail (Discrete), Φ P is four full rows and six scaled
    // ones, and (Φ P) Φᵀ four full columns and six scaled ones.
    if (m.tail_sparse) {
      Mat10 pp;
      pp.topRows<4>().noalias() = m.phi.topRows<4>().lazyProduct(p);
      pp.row(4) = m.phi(4, 4) * p.row(4) + m.phi(4, 6) * p.row(6);
      pp.row(5) = m.phi(5, 5) * p.row(5) + m.phi(5, 7) * p.row(7);
      for (int i = 6; i < kNx; ++i) pp.row(i) = m.phi(i, i) * p.row(i);
      p.leftCols<4>().noalias() = pp.lazyProduct(m.phi.topRows<4>().transpose());
      p.col(4) = m.phi(4, 4) * pp.col(4) + m.phi(4, 6) * pp.col(6);
      p.col(5) = m.phi(5, 5) * pp.col(5) + m.phi(5, 7) * pp.col(7);
      for (int i = 6; i < kNx; ++i) p.col(i) = m.phi(i, i) * pp.col(i);
    } else {
      const Mat10 pp = m.phi.lazyProduct(p);
      p.triangularView<Eigen::Lower>() = pp.lazyProduct(m.phi.transpose());
    }
    p.triangularView<Eigen::Lower>() += m.q;
    p.triangularView<Eigen::StrictlyUpper>() = p.transpose();
  }
  return g;
}

struct Model {
  Discrete m;
  Gains g;
};

struct Problem {
  std::span<const OeWindow> windows;
  std::shared_ptr<const Model> held;   // the filter, when the noise model is held
  Layout lay;
  std::vector<std::vector<Vec2>> y_um;  // positions relative to the window's first sample [µm]
  std::vector<int> active;              // windows in the fit (jackknife drops one)
  std::vector<int> free;                // parameters estimated (the others held)
  std::size_t n{0};
  Mat2 m_tot{Mat2::Zero()}, d_adm{Mat2::Zero()};
  double h{0};

  Problem(std::span<const OeWindow> ws, Layout l) : windows(ws), lay(l) {
    n = ws.front().x_m.size();
    h = 1.0 / ws.front().fs_hz;
    d_adm = ws.front().d_adm_nspm;
    for (std::size_t i = 0; i < ws.size(); ++i) {
      const auto& w = ws[i];
      if (w.x_m.size() != n || w.u_n.size() != n)
        throw std::invalid_argument("prediction-error fit: windows differ in length (trial " + std::to_string(w.trial) +
                                    ")");
      std::vector<Vec2> y(n);
      for (std::size_t k = 0; k < n; ++k) y[k] = (w.x_m[k] - w.x_m[0]) * 1e6;
      y_um.push_back(std::move(y));
      m_tot += w.m_total_kg;
      active.push_back(static_cast<int>(i));
    }
    m_tot /= static_cast<double>(ws.size());
    for (int i = 0; i < lay.size(); ++i) free.push_back(i);
  }

  // Perturbation response [m] of one window (exact ZOH simulation with the
  // window's own M_BSP); Box-Jenkins only.
  [[nodiscard]] std::vector<Vec2> response(const Eigen::VectorXd& p, std::size_t wi) const {
    return simulate_variational(windows[wi], unpack_d(p), unpack_k(p));
  }

  // Innovations [µm] of one window. Box-Jenkins: the filter runs on what the
  // perturbation response `resp` leaves (empty: nothing removed, for the
  // VAF); ARMAX-like: on the positions, with the perturbation as input when
  // `with_input`.
  void innovations(const Discrete& m, const Gains& g, std::size_t wi, const std::vector<Vec2>* resp,
                   bool with_input, std::vector<Vec2>& e) const {
    e.resize(n);
    const auto& w = windows[wi];
    const auto& y = y_um[wi];
    const bool sub = lay.bj && resp && !resp->empty();
    Vec10 z = Vec10::Zero();
    for (std::size_t k = 0; k < n; ++k) {
      const Vec2 yk = sub ? Vec2(y[k] - (*resp)[k] * 1e6) : y[k];
      const Vec2 ek = yk - z.head<2>();
      e[k] = ek;
      z.noalias() += g.k[k].lazyProduct(ek);
      z = phi_times(m, z);
      if (!lay.bj && with_input) z += m.gam * w.u_n[k];
    }
  }
};

void project(const Layout& l, Eigen::VectorXd& p) {
  for (int i = 0; i < 4; ++i) p(l.log0() + i) = std::clamp(p(l.log0() + i), kLogLo[i], kLogHi[i]);
}

double fd_step(const Layout& l, Eigen::Index i, double v) {
  return i >= l.log0() ? 1e-5 : 1e-6 * std::max(1.0, std::abs(v));
}

// Negative log-likelihood of the innovations, its gradient and the Fisher
// information (Åström 1980; Gupta & Mehra 1974):
//   NLL = ½ Σ (log det S + eᵀ S⁻¹ e)
//   F_ij = Σ ∂eᵀ/∂θi S⁻¹ ∂e/∂θj + ½ Σ tr(S⁻¹ ∂S/∂θi S⁻¹ ∂S/∂θj)
// with ∂e, ∂S by forward differences (the filter is smooth in θ).
struct Score {
  double nll{0};
  Eigen::VectorXd grad;
  Eigen::MatrixXd fisher;
  Eigen::MatrixXd trial_grad;  // gradient per trial (columns): the sandwich's meat
};

Model model_at(const Problem& pr, const Eigen::VectorXd& p) {
  // Box-Jenkins with the noise model held: the filter does not depend on D, K.
  if (pr.held && pr.lay.bj) return *pr.held;
  Model md;
  md.m = discretise(pr.lay, p, pr.m_tot, pr.d_adm, pr.h);
  md.g = riccati(md.m, pr.n, std::exp(p(pr.lay.log0() + 1)));
  return md;
}

double nll(const Problem& pr, const Eigen::VectorXd& p) {
  const auto md = model_at(pr, p);
  double v = 0.0;
  std::vector<Vec2> e;
  std::vector<Vec2> resp;
  for (const int wi : pr.active) {
    const auto uw = static_cast<std::size_t>(wi);
    if (pr.lay.bj) resp = pr.response(p, uw);
    pr.innovations(md.m, md.g, uw, &resp, true, e);
    for (std::size_t k = 0; k < pr.n; ++k) v += (md.g.l_inv[k] * e[k]).squaredNorm();
  }
  for (std::size_t k = 0; k < pr.n; ++k) v += static_cast<double>(pr.active.size()) * md.g.log_det[k];
  return 0.5 * v;
}

Score score(const Problem& pr, const Eigen::VectorXd& p) {
  const int np = pr.lay.size();
  const auto md0 = model_at(pr, p);
  const auto nw = pr.active.size();
  std::vector<std::vector<Vec2>> e0(nw), r0(nw);
  for (std::size_t a = 0; a < nw; ++a) {
    const auto uw = static_cast<std::size_t>(pr.active[a]);
    if (pr.lay.bj) r0[a] = pr.response(p, uw);
    pr.innovations(md0.m, md0.g, uw, &r0[a], true, e0[a]);
  }
  const auto unp = static_cast<std::size_t>(np);
  std::vector<std::vector<std::vector<Vec2>>> de(unp, std::vector<std::vector<Vec2>>(nw));
  std::vector<std::vector<Mat2>> ds(unp);
  for (const int i : pr.free) {
    Eigen::VectorXd pp = p;
    const double hstep = fd_step(pr.lay, i, p(i));
    pp(i) += hstep;
    // Box-Jenkins: D, K move only the perturbation response, the noise
    // parameters only the filter; each derivative recomputes only its part.
    const bool response_only = pr.lay.bj && i < 7;
    const bool filter_only = pr.lay.bj && i >= 7;
    const Model md = response_only ? md0 : model_at(pr, pp);
    auto& dsi = ds[static_cast<std::size_t>(i)];
    dsi.resize(pr.n);
    for (std::size_t k = 0; k < pr.n; ++k) dsi[k] = response_only ? Mat2::Zero() : Mat2((md.g.s[k] - md0.g.s[k]) / hstep);
    std::vector<Vec2> resp;
    for (std::size_t a = 0; a < nw; ++a) {
      const auto uw = static_cast<std::size_t>(pr.active[a]);
      auto& d = de[static_cast<std::size_t>(i)][a];
      if (pr.lay.bj && !filter_only) resp = pr.response(pp, uw);
      pr.innovations(md.m, md.g, uw, filter_only ? &r0[a] : &resp, true, d);
      for (std::size_t k = 0; k < pr.n; ++k) d[k] = (d[k] - e0[a][k]) / hstep;
    }
  }
  Score sc;
  sc.grad = Eigen::VectorXd::Zero(np);
  sc.fisher = Eigen::MatrixXd::Zero(np, np);
  sc.trial_grad = Eigen::MatrixXd::Zero(np, static_cast<Eigen::Index>(nw));
  const double w = static_cast<double>(nw);
  // With S = L Lᵀ, eᵀS⁻¹e = |L⁻¹e|²: the data terms are inner products of
  // whitened innovations and sensitivities, so each trial adds Jᵀ J and Jᵀ e
  // of its whitened sensitivity matrix J (2n × free) in one product.
  std::vector<int> with_ds;  // parameters that move the innovation covariance
  for (const int i : pr.free)
    if (!(pr.lay.bj && i < 7)) with_ds.push_back(i);
  const auto nf = static_cast<Eigen::Index>(pr.free.size());
  const auto rows = static_cast<Eigen::Index>(2 * pr.n);
  Eigen::MatrixXd jw(rows, nf);
  Eigen::VectorXd ew(rows);
  Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(nf, nf);
  for (std::size_t a = 0; a < nw; ++a) {
    for (std::size_t k = 0; k < pr.n; ++k) {
      const Mat2& li = md0.g.l_inv[k];
      const auto r = static_cast<Eigen::Index>(2 * k);
      ew.segment<2>(r) = li * e0[a][k];
      for (Eigen::Index f = 0; f < nf; ++f) jw.block<2, 1>(r, f) = li * de[static_cast<std::size_t>(pr.free[static_cast<std::size_t>(f)])][a][k];
    }
    sc.nll += 0.5 * ew.squaredNorm();
    jtj.selfadjointView<Eigen::Lower>().rankUpdate(jw.transpose());
    const Eigen::VectorXd ga = jw.transpose() * ew;
    for (Eigen::Index f = 0; f < nf; ++f) sc.trial_grad(pr.free[static_cast<std::size_t>(f)], static_cast<Eigen::Index>(a)) += ga(f);
  }
  for (Eigen::Index f = 0; f < nf; ++f)
    for (Eigen::Index g = 0; g <= f; ++g) {
      const int i = pr.free[static_cast<std::size_t>(f)], j = pr.free[static_cast<std::size_t>(g)];
      sc.fisher(i, j) += jtj(f, g);
      if (i != j) sc.fisher(j, i) += jtj(f, g);
    }
  // Terms of ∂S: ½ tr(S⁻¹∂S) − ½ eᵀS⁻¹ ∂S S⁻¹e in the gradient, and
  // ½ tr(S⁻¹∂S_i S⁻¹∂S_j) per trial in the Fisher information.
  std::vector<Mat2> sds(with_ds.size());
  for (std::size_t k = 0; k < pr.n; ++k) {
    const Mat2 sinv = md0.g.s[k].inverse();
    sc.nll += 0.5 * w * md0.g.log_det[k];
    for (std::size_t u = 0; u < with_ds.size(); ++u) sds[u] = sinv * ds[static_cast<std::size_t>(with_ds[u])][k];
    for (std::size_t u = 0; u < with_ds.size(); ++u) {
      const int i = with_ds[u];
      const auto& dsi = ds[static_cast<std::size_t>(i)][k];
      const double tr = 0.5 * sds[u].trace();
      for (std::size_t a = 0; a < nw; ++a) {
        const Vec2 se = sinv * e0[a][k];
        sc.trial_grad(i, static_cast<Eigen::Index>(a)) += tr - 0.5 * se.dot(dsi * se);
      }
      for (std::size_t v = u; v < with_ds.size(); ++v) {
        const int j = with_ds[v];
        const double t = 0.5 * w * (sds[u] * sds[v]).trace();
        sc.fisher(i, j) += t;
        if (j != i) sc.fisher(j, i) += t;
      }
    }
  }
  sc.grad = sc.trial_grad.rowwise().sum();
  return sc;
}

struct ScoringResult {
  Eigen::VectorXd theta;
  Score at;
  int iterations{0};
  bool converged{false};
};

// Fisher scoring with Levenberg damping: the standard maximum-likelihood
// iteration for state-space models; near the optimum it converges like
// Gauss-Newton on every parameter, noise parameters included.
ScoringResult maximise_likelihood(const Problem& pr, Eigen::VectorXd p, int max_iter, double tol_nats) {
  ScoringResult out;
  project(pr.lay, p);
  Score sc = score(pr, p);
  double lambda = 1e-2;
  for (int it = 0; it < max_iter; ++it) {
    out.iterations = it + 1;
    bool improved = false;
    // Active set: a noise parameter at its bound whose gradient points out of
    // the box stays there this iteration (noise-free data drive σ_n and r to
    // their floors; projecting a full step there would stall the iteration).
    std::vector<int> act;
    for (const int i : pr.free) {
      if (i >= pr.lay.log0()) {
        const int b = i - pr.lay.log0();
        if ((p(i) <= kLogLo[b] && sc.grad(i) > 0) || (p(i) >= kLogHi[b] && sc.grad(i) < 0)) continue;
      }
      act.push_back(i);
    }
    const auto nf = static_cast<Eigen::Index>(act.size());
    Eigen::MatrixXd ff(nf, nf);
    Eigen::VectorXd gf(nf);
    for (Eigen::Index a = 0; a < nf; ++a) {
      gf(a) = sc.grad(act[static_cast<std::size_t>(a)]);
      for (Eigen::Index b = 0; b < nf; ++b)
        ff(a, b) = sc.fisher(act[static_cast<std::size_t>(a)], act[static_cast<std::size_t>(b)]);
    }
    for (int tries = 0; tries < 14; ++tries) {
      Eigen::MatrixXd a = ff;
      a.diagonal() += lambda * ff.diagonal().cwiseMax(1e-30);
      const Eigen::VectorXd step = a.ldlt().solve(gf);
      Eigen::VectorXd pn = p;
      for (Eigen::Index q = 0; q < nf; ++q) pn(act[static_cast<std::size_t>(q)]) -= step(q);
      project(pr.lay, pn);
      const double cn = nll(pr, pn);
      if (std::isfinite(cn) && cn < sc.nll) {
        const double dec = sc.nll - cn;
        p = pn;
        lambda = std::max(lambda / 10.0, 1e-8);
        improved = true;
        // Default 1e-6 nats: far below the likelihood's statistical
        // resolution (~0.5 nats); neighbouring fits settle for less (PemSettings).
        if (dec < tol_nats + 1e-9 * std::abs(cn)) out.converged = true;
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) {
      out.converged = true;
      break;
    }
    sc = score(pr, p);
    if (out.converged) break;
  }
  out.theta = p;
  out.at = std::move(sc);
  return out;
}

}  // namespace

OeWindow make_pem_window(const SessionInfo& info, const TrialData& trial, const Mat2& m_bsp, const PemSettings& s) {
  OeSettings span;
  span.t_pre_s = s.t_pre_s;
  span.t_est_s = s.t_est_s;
  return make_oe_window(info, trial, m_bsp, span);
}

ImpedanceEstimate fit_prediction_error(std::span<const OeWindow> windows, const PemSettings& s) {
  if (windows.empty()) throw std::invalid_argument("prediction-error fit: no perturbed trials");
  const Layout lay{s.structure == PemStructure::box_jenkins};
  Problem pr(windows, lay);
  const int np = lay.size(), L = lay.log0();
  Eigen::VectorXd p0(np);
  // A generic arm and generic noise; the optimiser moves far from both.
  p0.head(7) << 10.0, 0.0, 0.0, 10.0, 200.0, 0.0, 200.0;
  if (lay.bj) p0.segment(7, 7) = p0.head(7);
  p0.segment(L, 4) << std::log(1e3), std::log(0.1), std::log(0.05), std::log(0.1);
  {
    // Measurement noise from the data: white noise of variance r gives
    // second differences of variance 6 r, while the arm's motion adds
    // ~ (a h²)² ≈ 1e-6 µm² at 4 kHz. Starting r there, not at the generic
    // 0.1 µm², keeps the first steps sane on coarse encoders (a start
    // 10⁴ nats from the optimum sent Fisher scoring to a far local optimum).
    double ss = 0.0;
    std::size_t cnt = 0;
    for (const auto& y : pr.y_um)
      for (std::size_t k = 1; k + 1 < y.size(); ++k) {
        ss += (y[k + 1] - 2.0 * y[k] + y[k - 1]).squaredNorm();
        cnt += 2;
      }
    if (cnt > 0 && ss > 0) p0(L + 3) = std::clamp(std::log(ss / static_cast<double>(cnt) / 6.0), kLogLo[3], kLogHi[3]);
  }
  if (s.warm_start && !s.hold_disturbance && s.start_disturbance.box_jenkins == lay.bj) {
    const auto& sd = s.start_disturbance;
    p0.head(7) << s.start_d_nspm(0, 0), s.start_d_nspm(0, 1), s.start_d_nspm(1, 0), s.start_d_nspm(1, 1), s.start_k_npm(0, 0),
        0.5 * (s.start_k_npm(0, 1) + s.start_k_npm(1, 0)), s.start_k_npm(1, 1);
    if (lay.bj) p0.segment(7, 7) << sd.d_nspm(0, 0), sd.d_nspm(0, 1), sd.d_nspm(1, 0), sd.d_nspm(1, 1), sd.k_npm(0, 0),
        0.5 * (sd.k_npm(0, 1) + sd.k_npm(1, 0)), sd.k_npm(1, 1);
    p0.segment(L, 4) << std::log(sd.drive_psd), std::log(sd.motor_noise_n), std::log(sd.motor_tau_s),
        std::log(sd.meas_std_m * sd.meas_std_m * 1e12);
    if (!p0.allFinite()) throw std::invalid_argument("prediction-error fit: the warm start is not finite");
  }
  if (s.hold_disturbance) {
    const auto& fd = s.fixed_disturbance;
    if (fd.box_jenkins != lay.bj)
      throw std::invalid_argument("prediction-error fit: the held disturbance model's structure does not match the settings");
    if (lay.bj) p0.segment(7, 7) << fd.d_nspm(0, 0), fd.d_nspm(0, 1), fd.d_nspm(1, 0), fd.d_nspm(1, 1), fd.k_npm(0, 0),
        fd.k_npm(0, 1), fd.k_npm(1, 1);
    p0.segment(L, 4) << std::log(fd.drive_psd), std::log(fd.motor_noise_n), std::log(fd.motor_tau_s),
        std::log(fd.meas_std_m * fd.meas_std_m * 1e12);
    pr.free.resize(7);  // D, K only
    if (lay.bj) {
      auto md = std::make_shared<Model>();
      md->m = discretise(lay, p0, pr.m_tot, pr.d_adm, pr.h);
      md->g = riccati(md->m, pr.n, std::exp(p0(L + 1)));
      pr.held = std::move(md);
    }
  }
  const auto fit = maximise_likelihood(pr, p0, s.max_iterations, s.tolerance_nats);
  const Eigen::VectorXd& p = fit.theta;

  ImpedanceEstimate e;
  e.d_nspm = unpack_d(p);
  e.k_npm = unpack_k(p);
  Mat2 mean = Mat2::Zero();
  for (const auto& w : windows) mean += w.m_bsp_kg;
  e.m_kg = mean / static_cast<double>(windows.size());
  e.iterations = fit.iterations;

  // Standard errors from the inverse Fisher information of the estimated
  // parameters (noise parameters included, so their uncertainty propagates
  // into D and K); D, K are the first 7 of them.
  const auto nf = static_cast<Eigen::Index>(pr.free.size());
  Eigen::MatrixXd f(nf, nf), g(nf, fit.at.trial_grad.cols());
  for (Eigen::Index a = 0; a < nf; ++a) {
    g.row(a) = fit.at.trial_grad.row(pr.free[static_cast<std::size_t>(a)]);
    for (Eigen::Index b = 0; b < nf; ++b)
      f(a, b) = fit.at.fisher(pr.free[static_cast<std::size_t>(a)], pr.free[static_cast<std::size_t>(b)]);
  }
  const Eigen::VectorXd sc = f.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd fn = sc.asDiagonal() * f * sc.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(fn);
  const auto& ev = eig.eigenvalues();
  e.condition = ev(0) > 0 ? std::sqrt(ev(ev.size() - 1) / ev(0)) : std::numeric_limits<double>::infinity();
  const Eigen::MatrixXd cov =
      sc.asDiagonal() *
      (eig.eigenvectors() * ev.cwiseMax(1e-300).cwiseInverse().asDiagonal() * eig.eigenvectors().transpose()) *
      sc.asDiagonal();
  const int nw = static_cast<int>(windows.size());
  Eigen::VectorXd se = cov.diagonal().head(7).cwiseSqrt();
  e.se_kind = "Fisher information";
  e.ci_factor = 1.96;
  if (s.se == PemSe::sandwich && nw >= 3) {
    // Sandwich (Huber-White) over trials: F⁻¹ (Σ g_a g_aᵀ) F⁻¹ stays honest
    // when the noise model is only approximately right (the real person's
    // noise is not exactly an OU force); trials are the independent units.
    const Eigen::MatrixXd meat = g * g.transpose() * (static_cast<double>(nw) / (nw - 1));
    se = (cov * meat * cov).diagonal().head(7).cwiseSqrt();
    e.se_kind = "sandwich over trials";
    e.ci_factor = t_quantile_975(nw - 1);
  }
  if (s.se == PemSe::jackknife && nw >= 3) {
    std::vector<Eigen::VectorXd> loo;
    for (int i = 0; i < nw; ++i) {
      Problem sub = pr;
      sub.active.erase(sub.active.begin() + i);
      loo.push_back(maximise_likelihood(sub, p, s.max_iterations, s.tolerance_nats).theta.head(7));
    }
    se = jackknife_se(loo);
    e.se_kind = "jackknife over trials";
    e.ci_factor = t_quantile_975(nw - 1);
  }
  e.d_se << se(0), se(1), se(2), se(3);
  e.k_se << se(4), se(5), se(5), se(6);

  // Fit quality: innovation RMS, and the share of the input-free model's
  // one-step prediction error that the perturbation model explains.
  const auto md = model_at(pr, p);
  double ss = 0.0, ss0 = 0.0;
  std::vector<Vec2> ev1, ev0;
  std::vector<Vec2> resp;
  for (const int wi : pr.active) {
    const auto uw = static_cast<std::size_t>(wi);
    if (lay.bj) resp = pr.response(p, uw);
    pr.innovations(md.m, md.g, uw, &resp, true, ev1);
    pr.innovations(md.m, md.g, uw, nullptr, false, ev0);
    for (std::size_t k = 0; k < pr.n; ++k) ss += ev1[k].squaredNorm(), ss0 += ev0[k].squaredNorm();
  }
  const double rows = static_cast<double>(2 * pr.n * pr.active.size());
  e.residual_rms = std::sqrt(ss / rows) * 1e-6;
  e.vaf = ss0 > 0 ? 1.0 - ss / ss0 : 0.0;
  e.n_samples = static_cast<int>(pr.n * pr.active.size());
  e.n_params = np;
  e.n_trials = nw;
  flag_identifiability(e);
  if (!fit.converged) {
    e.identifiable = false;
    if (e.flag.empty())
      e.flag = "prediction-error fit did not converge in " + std::to_string(fit.iterations) + " iterations";
  }
  DisturbanceModel dm;
  dm.box_jenkins = lay.bj;
  dm.drive_psd = std::exp(p(L));
  dm.motor_noise_n = std::exp(p(L + 1));
  dm.motor_tau_s = std::exp(p(L + 2));
  dm.meas_std_m = std::sqrt(std::exp(p(L + 3))) * 1e-6;
  dm.neg_log_likelihood = fit.at.nll;
  disturbance_arm(lay, p, dm.d_nspm, dm.k_npm);
  e.disturbance = dm;
  return e;
}

std::vector<double> window_neg_log_likelihood(std::span<const OeWindow> windows, const PemSettings& s, const Mat2& d_nspm,
                                              const Mat2& k_npm, const DisturbanceModel& noise) {
  if (windows.empty()) return {};
  const Layout lay{s.structure == PemStructure::box_jenkins};
  if (noise.box_jenkins != lay.bj)
    throw std::invalid_argument("prediction-error likelihood: the noise model's structure does not match the settings");
  Problem pr(windows, lay);
  const int L = lay.log0();
  Eigen::VectorXd p(lay.size());
  p.head(7) << d_nspm(0, 0), d_nspm(0, 1), d_nspm(1, 0), d_nspm(1, 1), k_npm(0, 0), k_npm(0, 1), k_npm(1, 1);
  if (lay.bj) p.segment(7, 7) << noise.d_nspm(0, 0), noise.d_nspm(0, 1), noise.d_nspm(1, 0), noise.d_nspm(1, 1), noise.k_npm(0, 0),
      noise.k_npm(0, 1), noise.k_npm(1, 1);
  p.segment(L, 4) << std::log(noise.drive_psd), std::log(noise.motor_noise_n), std::log(noise.motor_tau_s),
      std::log(noise.meas_std_m * noise.meas_std_m * 1e12);
  const auto md = model_at(pr, p);
  std::vector<double> out;
  std::vector<Vec2> e, resp;
  for (std::size_t wi = 0; wi < windows.size(); ++wi) {
    if (lay.bj) resp = pr.response(p, wi);
    pr.innovations(md.m, md.g, wi, &resp, true, e);
    double v = 0.0;
    for (std::size_t k = 0; k < pr.n; ++k) v += (md.g.l_inv[k] * e[k]).squaredNorm() + md.g.log_det[k];
    out.push_back(0.5 * v);
  }
  return out;
}

}  // namespace manip::estimation
