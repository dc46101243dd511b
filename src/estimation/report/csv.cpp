#include "manip/estimation/report/csv.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::fmt;
using report_detail::mat;
using report_detail::create_output_dir;

void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path) {
  std::ofstream o(path);
  if (!o) throw manip::OutputError(path + ": cannot write CSV");
  o << "log,method,group,kind,trial,angle_deg,n_trials,D11,D12,D21,D22,K11,K12,K21,K22,"
       "D11_se,D12_se,D21_se,D22_se,K11_se,K12_se,K21_se,K22_se,vaf,identifiable\n";
  o << std::setprecision(10);
  auto row = [&](const std::string& log, const std::string& m, const std::string& g, const std::string& kind, int trial,
                 double ang, int n, const Mat2& d, const Mat2& k, const Mat2& dse, const Mat2& kse, double vaf, bool ok) {
    o << log << ',' << m << ',' << g << ",\"" << kind << "\"," << trial << ',' << ang << ',' << n;
    for (const Mat2* mm : {&d, &k, &dse, &kse})
      for (int i = 0; i < 4; ++i) o << ',' << (*mm)(i / 2, i % 2);
    o << ',' << vaf << ',' << (ok ? 1 : 0) << '\n';
  };
  for (const auto& [log, r] : reports) {
    for (const auto& s : r.summaries)
      row(log, s.method, s.group.label(), s.kind, -1, s.group.angle_deg, s.n_trials, s.d_nspm, s.k_npm, s.d_spread, s.k_spread, NAN, s.identifiable);
    for (const auto& t : r.trials)
      row(log, t.method, "trial", "per-trial fit", t.trial, t.angle_deg, 1, t.est.d_nspm, t.est.k_npm, t.est.d_se,
          t.est.k_se, t.est.vaf, t.est.identifiable);
  }
  if (!o) throw manip::OutputError(path + ": write failed");
}

}  // namespace manip::estimation
