#pragma once
// The interface every estimation method implements (docs/estimator.md,
// "Adding a method"). SessionEstimator prepares each perturbed trial once
// (isolated variational signals of eq. 21, M_BSP at onset of eq. 16, and the
// output-error / prediction-error windows the selected methods ask for), then
// asks each method for fits: per trial, or pooled over the session and over
// each perturbation angle. Summaries, reports and the CLI's method list are
// built from this interface and the registry (registry.hpp) alone.
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "manip/estimation/estimate.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

struct EstimatorSettings;

// The data a method fits; SessionEstimator builds only the windows some
// selected method needs (the variational windows always: they carry the
// trial numbers and angles). Bit flags, combine with |.
enum class DataWindow : unsigned {
  variational = 1,       // isolated Δ signals + M_BSP (paper §3.1, eq. 21)
  output_error = 2,      // raw positions around onset, OeSettings' span (output_error.hpp)
  prediction_error = 4,  // the same with PemSettings' span (pem.hpp)
};
constexpr DataWindow operator|(DataWindow a, DataWindow b) {
  return static_cast<DataWindow>(static_cast<unsigned>(a) | static_cast<unsigned>(b));
}
constexpr bool needs(DataWindow set, DataWindow w) { return (static_cast<unsigned>(set) & static_cast<unsigned>(w)) != 0; }

// All usable perturbed trials of a session, index i the same trial in every span.
struct SessionWindows {
  const SessionInfo* info{nullptr};
  const EstimatorSettings* settings{nullptr};
  std::span<const VariationalWindow> variational;
  std::span<const Mat2> m_bsp;                 // eq. 16 at each onset
  std::span<const OeWindow> output_error;      // empty unless a selected method needs it
  std::span<const OeWindow> prediction_error;  // empty unless a selected method needs it
};

struct FitRequest {
  std::span<const std::size_t> trials;  // indices into SessionWindows; one for a per-trial method
  // Per-angle pooled fits: the session fit of the same method if it succeeded,
  // else null (the session fit itself and per-trial fits get null too).
  const ImpedanceEstimate* session_fit{nullptr};
};

class Method {
 public:
  virtual ~Method() = default;
  [[nodiscard]] virtual std::string name() const = 0;         // --method value, JSON "method"
  [[nodiscard]] virtual std::string description() const = 0;  // one line for --help and docs
  // true: one fit per trial, summarised as mean (std) over trials;
  // false: pooled fits (session, then each angle) with their own SE.
  [[nodiscard]] virtual bool per_trial() const = 0;
  [[nodiscard]] virtual DataWindow windows() const = 0;
  // Throws std::exception when the data cannot be fitted; the message is
  // reported as a trial issue (per trial) or a warning (pooled).
  [[nodiscard]] virtual ImpedanceEstimate fit(const SessionWindows& data, const FitRequest& req) const = 0;
};

// The requested trials of `all` as a span: a view when they are contiguous
// (always so for one trial and for the session), else gathered into `storage`.
template <class T>
std::span<const T> select(std::span<const T> all, std::span<const std::size_t> idx, std::vector<T>& storage) {
  bool contiguous = !idx.empty();
  for (std::size_t k = 1; k < idx.size() && contiguous; ++k) contiguous = idx[k] == idx[0] + k;
  if (contiguous) return all.subspan(idx[0], idx.size());
  storage.clear();
  for (auto i : idx) storage.push_back(all[i]);
  return storage;
}

}  // namespace manip::estimation
