// impedance_study: the estimator accuracy study (docs/accuracy-study.md).
// Seeded synthetic sessions with a known linear impedance, each method run on
// each session; bias, spread and 95%-interval coverage per matrix element.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"
#include "manip/version.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/sim/linear_human.hpp"
#include "manip/sim/presets.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;

namespace {
double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const auto n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}
double quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto i = static_cast<std::size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}
const char* kElem[7] = {"D11", "D12", "D21", "D22", "K11", "K12", "K22"};
double elem(const Mat2& d, const Mat2& k, int e) { return e < 4 ? d(e / 2, e % 2) : (e == 4 ? k(0, 0) : e == 5 ? k(0, 1) : k(1, 1)); }

int run(int argc, char** argv) {
  namespace cli = manip::cli;
  CLI::App app{"impedance_study " + std::string(kVersion) +
                   ": accuracy of every estimator on seeded synthetic sessions with known D, K",
               "impedance_study"};
  cli::Common opt;
  opt.movements = 32;
  int sessions = 20;
  std::string json_path, persons = "table1,stiff", noises = "none,realistic";
  std::uint64_t seed0 = 1000;
  cli::add_version(app, "impedance_study");
  cli::add_quiet(app, opt.quiet)->description("no per-session progress on stderr");
  cli::add_out(app, opt.out, "the accuracy table (Markdown) to FILE instead of stdout");
  cli::add_force(app, opt.force);
  app.add_option("--sessions", sessions, "seeded sessions per condition")->check(CLI::Range(1, 100000))->capture_default_str();
  cli::add_movements(app, opt.movements, 1, 100000, "movements per session (24 perturbed + unperturbed)");
  const std::vector<std::string> kPersons = {"table1", "stiff"}, kNoises = {"none", "realistic"};
  // Each comma-list element checked, so a misspelt name is refused, not silently run as table1.
  auto each_of = [](const std::vector<std::string>& allowed) {
    return CLI::Validator(
        [allowed](std::string& s) -> std::string {
          std::stringstream ss(s);
          int n = 0;
          for (std::string t; std::getline(ss, t, ','); ++n)
            if (std::find(allowed.begin(), allowed.end(), t) == allowed.end())
              return "'" + t + "' is not one of " + cli::join(allowed);
          return n == 0 ? "empty list" : "";
        },
        "LIST");
  };
  app.add_option("--persons", persons, "comma list of " + cli::join(kPersons, ", "))->check(each_of(kPersons));
  app.add_option("--noise", noises, "comma list of " + cli::join(kNoises, ", "))->check(each_of(kNoises));
  app.add_option("--seed", seed0, "first seed");
  app.add_option("--json", json_path, "raw per-session results as JSON (kept if it exists, unless --force)");
  int oe_poly = -1;
  double oe_pre = -1;
  std::string methods = "all";
  app.add_option("--oe-poly-order", oe_poly, "output-error polynomial order (default: estimator default)")
      ->check(CLI::Range(0, 20));
  app.add_option("--oe-pre", oe_pre, "output-error data before onset [s] (default: estimator default)")
      ->check(cli::finite_range(0, 10));
  app.add_option("--methods", methods, "comma list of methods or 'all'");
  int prewhiten = -1;
  std::string pem_structure;
  double pem_pre = -1;
  app.add_option("--pem-structure", pem_structure, "prediction error: box-jenkins | armax (default: estimator default)")
      ->check(cli::one_of({"box-jenkins", "armax"}));
  app.add_option("--pem-pre", pem_pre, "prediction error: data before onset [s] (default: estimator default)")
      ->check(cli::finite_range(0, 10));
  app.add_option("--oe-prewhiten", prewhiten, "output-error prewhitening AR order (default: estimator default)")
      ->check(CLI::Range(0, 50));
  cli::set_exit_codes(app, {exit_code::kOk, exit_code::kUsage, exit_code::kOutput, exit_code::kInternal});
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  const int movements = opt.movements;
  // Outputs are checked before hours of computing, and written atomically at the end.
  std::optional<AtomicOutput> table_out, json_out;
  if (!opt.out.empty()) table_out.emplace(opt.out, opt.force);
  if (!json_path.empty()) json_out.emplace(json_path, opt.force);
  std::ostringstream table;
  if (!pem_structure.empty() && pem_structure != "box-jenkins" && pem_structure != "armax")
    throw UsageError("--pem-structure: must be box-jenkins or armax");
  auto split = [](const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    for (std::string t; std::getline(ss, t, ',');) out.push_back(t);
    return out;
  };
  // Without --out the table streams to stdout condition by condition, as before.
  auto flush_table = [&] {
    if (!table_out) {
      std::cout << table.str();
      std::cout.flush();
      table.str("");
    }
  };
  nlohmann::json raw = nlohmann::json::array();
  table << "| person | noise | method | element | truth | median est | median rel. error | IQR of rel. error | "
               "|rel. error| median | 95% CI coverage | median SE / |truth| |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& person : split(persons)) {
    for (const auto& noise : split(noises)) {
      // per method, per element: estimates, covered flags
      std::map<std::string, std::array<std::vector<double>, 7>> est, covered, rel_se;
      sim::LinearHumanParams truth_p = person == "stiff" ? sim::stiff_person() : sim::table1_person();
      for (int s = 0; s < sessions; ++s) {
        sim::SessionDesign d;
        d.n_movements = movements;
        d.seed = seed0 + static_cast<std::uint64_t>(s);
        d.write_twins = false;
        auto hp = truth_p;
        sim::apply_noise(sim::parse_noise_level(noise), d, hp);
        hp.sample_rate_hz = d.session.sample_rate_hz * d.substeps;
        sim::LinearImpedanceHuman human(hp);
        estimation::EstimatorSettings es;
        es.methods = methods == "all" ? estimation::all_methods() : split(methods);
        if (oe_poly >= 0) es.oe.poly_order = oe_poly;
        if (oe_pre >= 0) es.oe.t_pre_s = oe_pre;
        if (prewhiten >= 0) es.oe.prewhiten_order = prewhiten;
        if (pem_pre >= 0) es.pem.t_pre_s = pem_pre;
        if (pem_structure == "armax") es.pem.structure = estimation::PemStructure::armax;
        std::optional<estimation::SessionEstimator> se_or;
        try {
          se_or.emplace(es);
        } catch (const std::invalid_argument& e) {  // an unknown method name
          throw UsageError(std::string("--methods: ") + e.what());
        }
        auto& se = *se_or;
        estimation::TrialAssembler asmb(
            [&](const estimation::SessionInfo& info, estimation::TrialData&& t) { se.add_trial(info, std::move(t)); });
        sim::run_session(d, human, asmb);
        asmb.finish();
        const auto rep = se.finish(asmb.issues(), asmb.warnings());
        for (const auto& sm : rep.summaries) {
          if (!sm.group.is_session()) continue;
          nlohmann::json row = {{"person", person}, {"noise", noise}, {"seed", d.seed}, {"method", sm.method}};
          for (int e = 0; e < 7; ++e) {
            const double v = elem(sm.d_nspm, sm.k_npm, e);
            const double lo = elem(sm.d_lo, sm.k_lo, e), hi = elem(sm.d_hi, sm.k_hi, e);
            const double tv = elem(truth_p.d_nspm, truth_p.k_npm, e);
            est[sm.method][static_cast<std::size_t>(e)].push_back(v);
            if (std::isfinite(lo) && std::isfinite(hi))
              covered[sm.method][static_cast<std::size_t>(e)].push_back(lo <= tv && tv <= hi ? 1.0 : 0.0);
            // SE (pooled) or std over trials (per-trial methods), relative to the truth: the
            // spread the method itself claims, to set beside the spread it achieves.
            rel_se[sm.method][static_cast<std::size_t>(e)].push_back(elem(sm.d_spread, sm.k_spread, e) / std::abs(tv));
            row[kElem[e]] = v;
          }
          row["identifiable"] = sm.identifiable;
          raw.push_back(row);
        }
        if (!opt.quiet) std::cerr << "impedance_study: " << person << "/" << noise << " session " << s + 1 << "/" << sessions << "\n";
      }
      for (const auto& [method, vals] : est) {
        for (int e = 0; e < 7; ++e) {
          const double tv = elem(truth_p.d_nspm, truth_p.k_npm, e);
          std::vector<double> rel, absrel;
          for (double v : vals[static_cast<std::size_t>(e)]) {
            rel.push_back((v - tv) / std::abs(tv));
            absrel.push_back(std::abs(v - tv) / std::abs(tv));
          }
          const auto& cov = covered[method][static_cast<std::size_t>(e)];
          double c = NAN;
          if (!cov.empty()) {
            c = 0;
            for (double x : cov) c += x;
            c /= static_cast<double>(cov.size());
          }
          table << std::fixed << std::setprecision(3) << "| " << person << " | " << noise << " | " << method << " | "
                    << kElem[e] << " | " << tv << " | " << median(vals[static_cast<std::size_t>(e)]) << " | "
                    << median(rel) * 100 << "% | " << (quantile(rel, 0.75) - quantile(rel, 0.25)) * 100 << "% | "
                    << median(absrel) * 100 << "% | "
                    << (std::isfinite(c) ? std::to_string(static_cast<int>(std::lround(c * 100))) + "%" : "n/a")
                    << " | " << median(rel_se[method][static_cast<std::size_t>(e)]) * 100 << "% |\n";
        }
      }
      flush_table();
    }
  }
  auto write = [](AtomicOutput& o, const std::string& text) {
    if (std::fwrite(text.data(), 1, text.size(), o.stream()) != text.size())
      throw OutputError(o.path() + ": write failed");
    o.commit();
  };
  if (json_out) write(*json_out, raw.dump(1) + "\n");
  if (table_out) write(*table_out, table.str());
  return exit_code::kOk;
}

}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("impedance_study", run, argc, argv); }
