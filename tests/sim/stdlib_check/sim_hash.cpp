// Portability check of a seeded simulation (not part of the test binaries: it is
// compiled twice by run.sh, with GCC + libstdc++ and with Clang + libc++, and the
// two must print the same hash). Runs a seeded manip_sim session (linear
// person, realistic noise) and prints an FNV-1a hash of every LCM-encoded
// message in stream order, i.e. of the log's content.
#include <cstdio>
#include <vector>
#include "manip/sim/human_factory.hpp"
#include "manip/sim/presets.hpp"
#include "manip/sim/session_runner.hpp"
using namespace manip;
struct Hash final : logging::SessionHandler {
  std::uint64_t h{1469598103934665603ull};
  long n{0};
  template <class M> void add(const M& m) {
    std::vector<char> buf(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(buf.data(), 0, static_cast<int>(buf.size()));
    for (char c : buf) { h ^= static_cast<unsigned char>(c); h *= 1099511628211ull; }
    ++n;
  }
  void on_session(const manip::session_t& m) override { add(m); }
  void on_state(const manip::state_t& m) override { add(m); }
  void on_trial_event(const manip::trial_event_t& m) override { add(m); }
  void on_truth_state(const manip::state_t& m) override { add(m); }
  void on_truth_impedance(const manip::impedance_truth_t& m) override { add(m); }
};
int main() {
  sim::SessionDesign d;
  d.n_movements = 30;
  d.seed = 7;
  sim::LinearHumanParams lp = sim::table1_person();
  sim::apply_noise(sim::NoiseLevel::realistic, d, lp);
  lp.sample_rate_hz = d.session.sample_rate_hz * d.substeps;
  sim::LinearImpedanceHuman h(lp);
  Hash out;
  sim::run_session(d, h, out);
  std::printf("%ld messages, hash %016llx\n", out.n, static_cast<unsigned long long>(out.h));
}
