#include "manip/dsp/butterworth.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

// Transcription of scipy 1.10 scipy/signal/_filter_design.py: iirfilter ->
// buttap -> lp2lp_zpk / lp2hp_zpk -> bilinear_zpk -> zpk2sos(pairing='nearest').
// Complex arithmetic mirrors numpy's (Smith's division for complex / complex,
// sequential np.prod) so that the sections agree with scipy to a few ulp;
// the pairing logic is reproduced step by step because it decides which pole
// pair lands in which section (scipy's section order is part of the contract:
// the estimator and its fixtures compare section by section).

namespace manip::dsp {
namespace {

using cd = std::complex<double>;

// numpy's complex128 division (loops.c.src, Smith's algorithm).
cd np_div(cd a, cd b) {
  const double br = b.real(), bi = b.imag();
  if (std::fabs(br) >= std::fabs(bi)) {
    const double rat = bi / br;
    const double scl = 1.0 / (br + bi * rat);
    return {(a.real() + a.imag() * rat) * scl, (a.imag() - a.real() * rat) * scl};
  }
  const double rat = br / bi;
  const double scl = 1.0 / (bi + br * rat);
  return {(a.real() * rat + a.imag()) * scl, (a.imag() * rat - a.real()) * scl};
}

cd np_mul(cd a, cd b) {
  return {a.real() * b.real() - a.imag() * b.imag(), a.real() * b.imag() + a.imag() * b.real()};
}

bool isreal(cd z) { return z.imag() == 0.0; }

// _cplxreal: one element (positive imaginary part, averaged with its conjugate)
// per complex pair sorted by real part then |imag|, followed by the reals sorted.
std::vector<cd> cplxreal(std::vector<cd> z) {
  if (z.empty()) return z;
  const double tol = 100.0 * std::numeric_limits<double>::epsilon();
  // np.lexsort((abs(z.imag), z.real)) is a stable sort with real as primary key.
  std::stable_sort(z.begin(), z.end(), [](cd a, cd b) {
    if (a.real() != b.real()) return a.real() < b.real();
    return std::fabs(a.imag()) < std::fabs(b.imag());
  });
  std::vector<cd> zr, zp, zn;
  for (cd v : z) {
    if (std::fabs(v.imag()) <= tol * std::abs(v)) {
      zr.emplace_back(v.real(), 0.0);
    } else if (v.imag() > 0) {
      zp.push_back(v);
    } else {
      zn.push_back(v);
    }
  }
  if (zp.size() != zn.size())
    throw std::invalid_argument("butter: complex value without matching conjugate");
  // Runs of (approximately) equal real part are sorted by |imag|.
  std::size_t start = 0;
  while (start < zp.size()) {
    std::size_t stop = start + 1;
    while (stop < zp.size() && zp[stop].real() - zp[stop - 1].real() <= tol * std::abs(zp[stop - 1]))
      ++stop;
    auto by_imag = [](cd a, cd b) { return std::fabs(a.imag()) < std::fabs(b.imag()); };
    std::stable_sort(zp.begin() + static_cast<std::ptrdiff_t>(start),
                     zp.begin() + static_cast<std::ptrdiff_t>(stop), by_imag);
    std::stable_sort(zn.begin() + static_cast<std::ptrdiff_t>(start),
                     zn.begin() + static_cast<std::ptrdiff_t>(stop), by_imag);
    start = stop;
  }
  std::vector<cd> out;
  out.reserve(zp.size() + zr.size());
  for (std::size_t i = 0; i < zp.size(); ++i) {
    if (std::abs(zp[i] - std::conj(zn[i])) > tol * std::abs(zn[i]))
      throw std::invalid_argument("butter: complex value without matching conjugate");
    const cd c = zp[i] + std::conj(zn[i]);
    out.emplace_back(c.real() * 0.5, c.imag() * 0.5);
  }
  out.insert(out.end(), zr.begin(), zr.end());
  return out;
}

// np.argmin(np.abs(1 - np.abs(p))): the pole closest to the unit circle, first on ties.
std::size_t idx_worst(const std::vector<cd>& p, const std::vector<std::size_t>& candidates) {
  std::size_t best = candidates.front();
  double best_d = std::fabs(1.0 - std::abs(p[best]));
  for (std::size_t c : candidates) {
    const double d = std::fabs(1.0 - std::abs(p[c]));
    if (d < best_d) {
      best = c;
      best_d = d;
    }
  }
  return best;
}

enum class Which { real, complex, any };

// _nearest_real_complex_idx. numpy's argsort on these short arrays (< 17
// elements) is an insertion sort, i.e. stable: ties go to the lower index.
std::size_t nearest_idx(const std::vector<cd>& fro, cd to, Which which) {
  std::size_t best = fro.size();
  double best_d = 0.0;
  for (std::size_t i = 0; i < fro.size(); ++i) {
    if (which == Which::real && !isreal(fro[i])) continue;
    if (which == Which::complex && isreal(fro[i])) continue;
    const double d = std::abs(fro[i] - to);
    if (best == fro.size() || d < best_d) {
      best = i;
      best_d = d;
    }
  }
  if (best == fro.size()) throw std::logic_error("butter: zpk2sos found no zero to pair");
  return best;
}

// _single_zpksos with k = 1 for at most two zeros and exactly two poles (the
// only shapes a Butterworth design produces under 'nearest' pairing). np.poly of a
// conjugate pair or of real roots is real: [1, -(r1 + r2), r1 * r2].
Sos single_sos(const std::vector<cd>& z, cd p1, cd p2) {
  Sos s{};
  if (z.size() == 2) {
    const cd sum = z[0] + z[1];
    const cd prod = np_mul(z[0], z[1]);
    s.b0 = 1.0;
    s.b1 = -sum.real();
    s.b2 = prod.real();
  } else if (z.size() == 1) {  // b = [1, -z1] right-aligned in sos[:3]
    s.b0 = 0.0;
    s.b1 = 1.0;
    s.b2 = -z[0].real();
  } else {
    s.b2 = 1.0;
  }
  const cd psum = p1 + p2;
  const cd pprod = np_mul(p1, p2);
  s.a0 = 1.0;
  s.a1 = -psum.real();
  s.a2 = pprod.real();
  return s;
}

template <class T>
T take(std::vector<T>& v, std::size_t i) {
  T out = v[i];
  v.erase(v.begin() + static_cast<std::ptrdiff_t>(i));
  return out;
}

std::vector<std::size_t> all_indices(std::size_t n) {
  std::vector<std::size_t> idx(n);
  for (std::size_t i = 0; i < n; ++i) idx[i] = i;
  return idx;
}

std::vector<Sos> zpk2sos_nearest(std::vector<cd> z, std::vector<cd> p, double k) {
  if (p.size() < z.size()) p.resize(z.size(), cd{0.0, 0.0});
  if (z.size() < p.size()) z.resize(p.size(), cd{0.0, 0.0});
  const std::size_t n_sections = (p.size() + 1) / 2;
  if (p.size() % 2 == 1) {
    p.emplace_back(0.0, 0.0);
    z.emplace_back(0.0, 0.0);
  }
  z = cplxreal(std::move(z));
  p = cplxreal(std::move(p));

  auto n_real = [](const std::vector<cd>& v) {
    return static_cast<std::size_t>(std::count_if(v.begin(), v.end(), isreal));
  };

  std::vector<Sos> sos(n_sections);
  for (std::size_t si = n_sections; si-- > 0;) {
    const cd p1 = take(p, idx_worst(p, all_indices(p.size())));
    if (isreal(p1) && n_real(p) == 0) {
      // Special case (1): last remaining real pole, paired with the nearest
      // real zero into a first-order section padded with zeros.
      const cd z1 = take(z, nearest_idx(z, p1, Which::real));
      sos[si] = single_sos({z1, cd{0.0, 0.0}}, p1, cd{0.0, 0.0});
    } else if (p.size() + 1 == z.size() && !isreal(p1) && n_real(p) == 1 && n_real(z) == 1) {
      // Special case (2): one real pole and one real zero left; must pair
      // this complex pole with a complex zero.
      const cd z1 = take(z, nearest_idx(z, p1, Which::complex));
      sos[si] = single_sos({z1, std::conj(z1)}, p1, std::conj(p1));
    } else {
      cd p2;
      if (isreal(p1)) {
        std::vector<std::size_t> reals;
        for (std::size_t i = 0; i < p.size(); ++i)
          if (isreal(p[i])) reals.push_back(i);
        p2 = take(p, idx_worst(p, reals));
      } else {
        p2 = std::conj(p1);
      }
      if (!z.empty()) {
        const cd z1 = take(z, nearest_idx(z, p1, Which::any));
        if (!isreal(z1)) {
          sos[si] = single_sos({z1, std::conj(z1)}, p1, p2);
        } else if (!z.empty()) {
          const cd z2 = take(z, nearest_idx(z, p1, Which::real));
          sos[si] = single_sos({z1, z2}, p1, p2);
        } else {
          sos[si] = single_sos({z1}, p1, p2);
        }
      } else {
        sos[si] = single_sos({}, p1, p2);
      }
    }
  }
  sos[0].b0 *= k;
  sos[0].b1 *= k;
  sos[0].b2 *= k;
  return sos;
}

cd np_prod(const std::vector<cd>& v) {
  if (v.empty()) return {1.0, 0.0};
  cd acc = v[0];
  for (std::size_t i = 1; i < v.size(); ++i) acc = np_mul(acc, v[i]);
  return acc;
}

}  // namespace

std::vector<Sos> butter(int order, double fc_hz, double fs_hz, BandType type) {
  if (order < 1) throw std::invalid_argument("butter: order must be >= 1, got " + std::to_string(order));
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz))
    throw std::invalid_argument("butter: fs must be positive and finite");
  const double wn = 2.0 * fc_hz / fs_hz;
  if (!(wn > 0.0 && wn < 1.0))
    throw std::invalid_argument("butter: cut-off must satisfy 0 < fc < fs/2 (fc=" + std::to_string(fc_hz) +
                                ", fs/2=" + std::to_string(fs_hz / 2.0) + ")");
  const double pi = std::numbers::pi;
  const int n = order;

  // buttap: p = -exp(1j * pi * m / (2N)), m = -N+1, -N+3, ..., N-1. numpy
  // evaluates the complex division by 2N as a multiplication by 1/(2N).
  std::vector<cd> p(static_cast<std::size_t>(n));
  const double inv_2n = 1.0 / (2.0 * n);
  for (int i = 0; i < n; ++i) {
    const int m = -n + 1 + 2 * i;
    const double theta = (pi * m) * inv_2n;
    p[static_cast<std::size_t>(i)] = cd{-std::cos(theta), -std::sin(theta)};
  }
  std::vector<cd> z;
  double k = 1.0;

  // Prewarp for the bilinear transform with the normalised fs = 2.
  const double fs = 2.0;
  const double warped = 2.0 * fs * std::tan(pi * wn / fs);

  if (type == BandType::lowpass) {  // lp2lp_zpk
    for (cd& v : p) v = cd{warped * v.real(), warped * v.imag()};
    k = k * std::pow(warped, static_cast<double>(n));
  } else {  // lp2hp_zpk: zeros at the origin, k * real(prod(-z) / prod(-p))
    std::vector<cd> neg_p(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) neg_p[i] = -p[i];
    k = k * np_div(cd{1.0, 0.0}, np_prod(neg_p)).real();
    for (cd& v : p) v = np_div(cd{warped, 0.0}, v);
    z.assign(p.size(), cd{0.0, 0.0});
  }

  // bilinear_zpk(z, p, k, fs=2)
  const double fs2 = 2.0 * fs;
  std::vector<cd> zz, pz(p.size()), fs2_minus_p(p.size());
  const std::size_t degree = p.size() - z.size();
  double prod_z = 1.0;
  for (cd v : z) {
    zz.push_back(np_div(cd{fs2 + v.real(), v.imag()}, cd{fs2 - v.real(), -v.imag()}));
    prod_z *= fs2 - v.real();  // zeros are real (the origin) here
  }
  for (std::size_t i = 0; i < degree; ++i) zz.emplace_back(-1.0, 0.0);
  for (std::size_t i = 0; i < p.size(); ++i) {
    fs2_minus_p[i] = cd{fs2 - p[i].real(), -p[i].imag()};
    pz[i] = np_div(cd{fs2 + p[i].real(), p[i].imag()}, fs2_minus_p[i]);
  }
  k = k * np_div(cd{prod_z, 0.0}, np_prod(fs2_minus_p)).real();

  return zpk2sos_nearest(std::move(zz), std::move(pz), k);
}

}  // namespace manip::dsp
