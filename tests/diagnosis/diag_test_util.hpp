#pragma once
// Shared by the diagnosis tests: a synthetic record goes through the CSV file
// and the front end, exactly like a lab's record (the diagnosis never sees
// the generator's settings).
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/mechanisms.hpp"
#include "manip/diagnosis/single_joint.hpp"
#include "manip/diagnosis/synthetic.hpp"

namespace manip::diagnosis::test {

inline std::string tmp_path(const std::string& name) {
  static const std::string dir = manip::testutil::temp_dir("diag");  // removed at exit
  return dir + "/" + name;
}

struct Run {
  synthetic::Truth truth;
  Diagnosis diag;
};

inline Run run_synthetic(const synthetic::Options& o, int bootstrap = 50) {
  const auto g = synthetic::generate(o);
  const std::string path = tmp_path(std::string(synthetic::name(o.hidden)) + "_" + std::to_string(o.seed) + ".csv");
  synthetic::write_csv(g.record, path, o.seed % 2 == 0);
  const auto rec = read_single_joint_csv(path);
  std::filesystem::remove(path);
  const auto prep = prepare_single_joint(rec);
  EngineOptions eo;
  eo.bootstrap = bootstrap;
  return {g.truth, diagnose(prep.data, standard_library(), eo)};
}

inline double rel_err(double est, double truth) { return std::fabs(est - truth) / std::fabs(truth); }

// The library's mechanism with this id (nullptr if none).
inline const Mechanism* mechanism_by_id(const std::vector<std::unique_ptr<Mechanism>>& lib, const std::string& id) {
  for (const auto& m : lib)
    if (m->id() == id) return m.get();
  return nullptr;
}

// A record of n samples of the position pos(t) and zero torque, prepared
// with the torque sign fixed: for checking columns against analytic inputs.
template <class F>
SingleJointPrepared prepared_position(double dt, int n, F pos) {
  SingleJointRecord rec;
  rec.dt_s = dt;
  for (int i = 0; i < n; ++i) {
    rec.pos_rad.push_back(pos(i * dt));
    rec.torque_nm.push_back(0.0);
  }
  SingleJointOptions so;
  so.torque_sign = 1;
  return prepare_single_joint(rec, so);
}

}  // namespace manip::diagnosis::test
