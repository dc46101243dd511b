#include "manip/estimation/report/signals.hpp"

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

void export_signals(const Report& r, const std::string& dir) {
  create_output_dir(dir);
  for (const auto& w : r.windows) {
    const std::string path = dir + "/trial_" + std::to_string(w.trial) + ".csv";
    std::ofstream o(path);
    if (!o) throw manip::OutputError(path + ": cannot write");
    o << std::setprecision(12);
    o << "t_s,dx1_m,dx2_m,dxd1_mps,dxd2_mps,dxdd1_mps2,dxdd2_mps2,du_ext_adm1_n,du_ext_adm2_n,du_ext_force1_n,"
         "du_ext_force2_n,u_pert1_n,u_pert2_n"
      << (w.dx_true.empty() ? "" : ",dx_true1_m,dx_true2_m") << "\n";
    for (std::size_t k = 0; k < w.size(); ++k) {
      o << static_cast<double>(k) / w.fs_hz;
      for (const auto* v : {&w.dx, &w.dxd, &w.dxdd, &w.du_ext_adm, &w.du_ext_force, &w.u_pert})
        o << ',' << (*v)[k].x() << ',' << (*v)[k].y();
      if (!w.dx_true.empty()) o << ',' << w.dx_true[k].x() << ',' << w.dx_true[k].y();
      o << '\n';
    }
  }
}

}  // namespace manip::estimation
