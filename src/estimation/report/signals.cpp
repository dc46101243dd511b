#include "manip/estimation/report/signals.hpp"

#include <filesystem>
#include <iomanip>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::create_output_dir;

void export_signals(const Report& r, const std::string& dir, bool force) {
  create_output_dir(dir);
  std::vector<std::pair<std::string, std::string>> files;
  for (const auto& w : r.windows) {
    const std::string path = dir + "/trial_" + std::to_string(w.trial) + ".csv";
    if (!force && std::filesystem::exists(path)) throw manip::OutputError(path + ": exists (pass --force to overwrite it)");
    const bool truth = !w.dx_true.empty() && w.dxd_true.size() == w.size() && w.dxdd_true.size() == w.size() &&
                       w.du_ext_true.size() == w.size();
    std::ostringstream o;
    o << std::setprecision(12);
    o << "t_s,dx1_m,dx2_m,dxd1_mps,dxd2_mps,dxdd1_mps2,dxdd2_mps2,du_ext_adm1_n,du_ext_adm2_n,du_ext_force1_n,"
         "du_ext_force2_n,u_pert1_n,u_pert2_n"
      << (w.dx_true.empty() ? "" : ",dx_true1_m,dx_true2_m")
      << (truth ? ",dxd_true1_mps,dxd_true2_mps,dxdd_true1_mps2,dxdd_true2_mps2,du_ext_true1_n,du_ext_true2_n" : "")
      << "\n";
    for (std::size_t k = 0; k < w.size(); ++k) {
      o << static_cast<double>(k) / w.fs_hz;
      for (const auto* v : {&w.dx, &w.dxd, &w.dxdd, &w.du_ext_adm, &w.du_ext_force, &w.u_pert})
        o << ',' << (*v)[k].x() << ',' << (*v)[k].y();
      if (!w.dx_true.empty()) o << ',' << w.dx_true[k].x() << ',' << w.dx_true[k].y();
      if (truth)
        for (const auto* v : {&w.dxd_true, &w.dxdd_true, &w.du_ext_true}) o << ',' << (*v)[k].x() << ',' << (*v)[k].y();
      o << '\n';
    }
    files.emplace_back(path, o.str());
  }
  for (const auto& [path, text] : files) write_file_atomically(path, text, force);
}

}  // namespace manip::estimation
