#include "manip/estimation/settings.hpp"

#include "manip/common/yaml_reader.hpp"

namespace manip::estimation {

EstimatorSettings load_estimator_settings(const std::string& path, EstimatorSettings s) {
  const YAML::Node root = manip::yaml::load_file(path);
  manip::yaml::Section y(path, root, "");
  auto positive = [](double v) { return v > 0; };
  if (y.has("methods")) {
    const YAML::Node n = y.get("methods");
    if (!n.IsSequence() || n.size() == 0) y.fail("methods", "expected a non-empty list of method names");
    s.methods.clear();
    for (std::size_t i = 0; i < n.size(); ++i) {
      if (!n[i].IsScalar()) y.fail_node(n[i], "methods", "expected a method name");
      s.methods.push_back(n[i].Scalar());
    }
    if (s.methods.size() == 1 && s.methods[0] == "all") s.methods = all_methods();
    for (const auto& m : s.methods)
      if (!find_method(m)) y.fail("methods", "unknown method '" + m + "' (known: " + method_list() + ", all)");
  }
  if (y.has("sg_order")) s.pipeline.sg_order = static_cast<int>(y.integer("sg_order", 1, 10));
  if (y.has("sg_cutoff_hz")) s.pipeline.sg_cutoff_hz = y.number("sg_cutoff_hz", positive, "must be positive");
  if (y.has("sg_window")) {
    s.pipeline.sg_window = static_cast<int>(y.integer("sg_window", 0, kMaxSgWindow));
    if (s.pipeline.sg_window != 0 && (s.pipeline.sg_window % 2 == 0 || s.pipeline.sg_window < kMinSgWindow))
      y.fail("sg_window", "must be odd and >= " + std::to_string(kMinSgWindow) + " (or 0 for automatic)");
  }
  if (y.has("hp_order")) s.pipeline.hp_order = static_cast<int>(y.integer("hp_order", 1, 10));
  if (y.has("hp_cutoff_hz")) {
    const YAML::Node n = y.get("hp_cutoff_hz");
    if (n.IsScalar() && n.Scalar() == "auto") {
      s.cutoff_auto = true;
    } else {
      s.cutoff_auto = false;
      s.pipeline.hp_cutoff_hz = y.number("hp_cutoff_hz", [](double v) { return v > 0 && v <= kMaxCutoffHz; },
                                         "must be in (0, 100] Hz (kMaxCutoffHz) or 'auto'");
    }
  }
  if (y.has("cutoff_auto_threshold_db")) s.cutoff_auto_threshold_db = y.any_number("cutoff_auto_threshold_db");
  if (y.has("psd_nfft")) s.psd_nfft = static_cast<int>(y.integer("psd_nfft", 256, 1 << 24));
  if (y.has("t_est_s")) {
    s.pipeline.t_est_s = y.number("t_est_s", [](double v) { return v > 0 && v <= 1.0; }, "must be in (0, 1] s");
    s.oe.t_est_s = s.pem.t_est_s = s.pipeline.t_est_s;
  }
  if (y.has("k_model"))
    s.ls.k_model = y.choice("k_model", {"symmetric", "full"}) == "symmetric" ? StiffnessModel::symmetric : StiffnessModel::full;
  if (y.has("estimate_m")) s.ls.estimate_m = y.boolean("estimate_m");
  if (y.has("force_source"))
    s.ls.force = y.choice("force_source", {"admittance", "sensor"}) == "admittance" ? ForceSource::admittance : ForceSource::sensor;
  if (y.has("position_source"))
    s.position = *parse_position_source(y.choice("position_source", {"encoder", "reference", "auto", "tracked"}));
  if (y.has("oe_t_pre_s"))
    s.oe.t_pre_s = y.number("oe_t_pre_s", [](double v) { return v >= 0 && v <= 0.5; }, "must be in [0, 0.5] s");
  if (y.has("oe_poly_order")) s.oe.poly_order = static_cast<int>(y.integer("oe_poly_order", 0, 8));
  if (y.has("oe_max_iterations")) s.oe.max_iterations = static_cast<int>(y.integer("oe_max_iterations", 1, 1000000));
  if (y.has("oe_jackknife")) s.oe.jackknife = y.boolean("oe_jackknife");
  if (y.has("oe_prewhiten_order")) s.oe.prewhiten_order = static_cast<int>(y.integer("oe_prewhiten_order", 0, 20));
  if (y.has("pem_t_pre_s"))
    s.pem.t_pre_s = y.number("pem_t_pre_s", [](double v) { return v >= 0.01 && v <= 0.5; }, "must be in [0.01, 0.5] s");
  if (y.has("pem_max_iterations")) s.pem.max_iterations = static_cast<int>(y.integer("pem_max_iterations", 1, 1000000));
  if (y.has("pem_structure"))
    s.pem.structure = y.choice("pem_structure", {"box-jenkins", "armax"}) == "box-jenkins" ? PemStructure::box_jenkins
                                                                                         : PemStructure::armax;
  if (y.has("pem_se")) {
    const auto se = y.choice("pem_se", {"sandwich", "fisher", "jackknife"});
    s.pem.se = se == "sandwich" ? PemSe::sandwich : (se == "fisher" ? PemSe::fisher : PemSe::jackknife);
  }
  y.finish();
  return s;
}

nlohmann::json settings_to_json(const EstimatorSettings& s) {
  const auto& p = s.pipeline;
  return {{"methods", s.methods},
          {"sg_order", p.sg_order},
          {"sg_cutoff_hz", p.sg_cutoff_hz},
          {"sg_window", p.sg_window},
          {"hp_order", p.hp_order},
          {"hp_cutoff_hz", p.hp_cutoff_hz},
          {"cutoff_auto", s.cutoff_auto},
          {"cutoff_auto_threshold_db", s.cutoff_auto_threshold_db},
          {"psd_nfft", s.psd_nfft},
          {"t_est_s", p.t_est_s},
          {"k_model", s.ls.k_model == StiffnessModel::symmetric ? "symmetric" : "full"},
          {"estimate_m", s.ls.estimate_m},
          {"force_source", s.ls.force == ForceSource::admittance ? "admittance" : "sensor"},
          {"position_source", to_string(s.position)},
          {"oe_t_pre_s", s.oe.t_pre_s},
          {"oe_t_est_s", s.oe.t_est_s},
          {"oe_poly_order", s.oe.poly_order},
          {"oe_max_iterations", s.oe.max_iterations},
          {"oe_jackknife", s.oe.jackknife},
          {"oe_prewhiten_order", s.oe.prewhiten_order},
          {"pem_t_pre_s", s.pem.t_pre_s},
          {"pem_t_est_s", s.pem.t_est_s},
          {"pem_structure", s.pem.structure == PemStructure::box_jenkins ? "box-jenkins" : "armax"},
          {"pem_se", s.pem.se == PemSe::sandwich ? "sandwich" : (s.pem.se == PemSe::fisher ? "fisher" : "jackknife")},
          {"pem_max_iterations", s.pem.max_iterations}};
}

}  // namespace manip::estimation
