#include "manip/estimation/group.hpp"

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <map>
#include <sstream>

#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::element;
using report_detail::num;
using report_detail::TextTable;
using report_detail::with_interval;

namespace {

// What must be equal for two sessions to be pooled: the estimator settings
// actually used (the resolved SG window included) and the sample rate.
std::string configuration_key(const Report& r) {
  nlohmann::json j = settings_to_json(r.settings);
  j["sample_rate_hz"] = r.info.sample_rate_hz;
  j["cutoff_used_hz"] = r.cutoff_used_hz;
  return j.dump();
}

std::string val(double v) {
  if (!std::isfinite(v)) return {};
  std::ostringstream o;
  o << std::setprecision(10) << v;
  return o.str();
}

std::string quote(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

}  // namespace

std::vector<GroupTable> group_tables(const std::vector<std::pair<std::string, Report>>& reports,
                                     const std::vector<std::string>& methods) {
  std::vector<std::string> keys;  // in order of first appearance
  std::map<std::string, std::vector<std::size_t>> by_key;
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const auto k = configuration_key(reports[i].second);
    if (!by_key.count(k)) keys.push_back(k);
    by_key[k].push_back(i);
  }
  std::map<std::string, int> id_count;
  for (const auto& [log, r] : reports) ++id_count[r.info.participant_id];
  std::vector<GroupTable> out;
  for (std::size_t c = 0; c < keys.size(); ++c) {
    const auto& idx = by_key[keys[c]];
    const Report& first = reports[idx.front()].second;
    for (const auto& m : methods) {
      GroupTable g;
      g.method = m;
      g.configuration = static_cast<int>(c) + 1;
      g.n_configurations = static_cast<int>(keys.size());
      std::ostringstream ct;
      ct << num(first.info.sample_rate_hz) << " Hz, high-pass " << num(first.cutoff_used_hz) << " Hz, SG window "
         << first.sg_window << ", T_est " << num(first.settings.pipeline.t_est_s) << " s";
      g.configuration_text = ct.str();
      for (std::size_t i : idx) {
        const auto& [log, r] = reports[i];
        for (const auto& s : r.summaries)
          if (s.method == m && s.group.is_session()) {
            std::string p = r.info.participant_id.empty() ? std::filesystem::path(log).stem().string() : r.info.participant_id;
            if (id_count[r.info.participant_id] > 1) p += " (" + std::filesystem::path(log).stem().string() + ")";
            g.members.push_back({p, log, s});
          }
      }
      if (g.members.empty()) continue;
      const double n = g.n();
      for (const auto& mem : g.members) {
        g.d_mean += mem.session.d_nspm / n;
        g.k_mean += mem.session.k_npm / n;
      }
      if (g.n() >= 2) {
        for (const auto& mem : g.members) {
          g.d_std += (mem.session.d_nspm - g.d_mean).cwiseAbs2() / (n - 1.0);
          g.k_std += (mem.session.k_npm - g.k_mean).cwiseAbs2() / (n - 1.0);
        }
        g.d_std = g.d_std.cwiseSqrt();
        g.k_std = g.k_std.cwiseSqrt();
      } else {
        g.d_std.setConstant(std::numeric_limits<double>::quiet_NaN());
        g.k_std.setConstant(std::numeric_limits<double>::quiet_NaN());
      }
      out.push_back(std::move(g));
    }
  }
  return out;
}

std::string group_text(const std::vector<GroupTable>& tables) {
  std::ostringstream o;
  for (const auto& g : tables) {
    o << "\ngroup (Table 1): method " << g.method
      << (g.method == default_method() ? " (default, recommended)" : "")
      << (method_bias_note(g.method).empty() ? "" : " (BIASED)") << ", " << g.n() << " participants";
    if (g.n_configurations > 1)
      o << ", configuration " << g.configuration << " of " << g.n_configurations << " (" << g.configuration_text
        << "; logs with different configurations are not pooled)";
    o << "\n";
    for (int which = 0; which < 2; ++which) {
      const char* m = which == 0 ? "D" : "K";
      TextTable t({"participant", std::string(m) + "11 [" + (which == 0 ? "N s/m" : "N/m") + "]", std::string(m) + "12",
                   std::string(m) + "21", std::string(m) + "22", "identifiable"});
      for (const auto& mem : g.members) {
        const auto& s = mem.session;
        const Mat2& v = which == 0 ? s.d_nspm : s.k_npm;
        const Mat2& lo = which == 0 ? s.d_lo : s.k_lo;
        const Mat2& hi = which == 0 ? s.d_hi : s.k_hi;
        std::vector<std::string> row{mem.participant};
        for (int i = 0; i < 4; ++i) row.push_back(with_interval(v(i / 2, i % 2), lo(i / 2, i % 2), hi(i / 2, i % 2)));
        row.push_back(s.identifiable ? "yes" : "NO: " + s.flag);
        t.add(row);
      }
      const Mat2& mean = which == 0 ? g.d_mean : g.k_mean;
      const Mat2& sd = which == 0 ? g.d_std : g.k_std;
      std::vector<std::string> row{"mean (std), n = " + std::to_string(g.n())};
      for (int i = 0; i < 4; ++i) row.push_back(num(mean(i / 2, i % 2)) + " (" + num(sd(i / 2, i % 2)) + ")");
      row.push_back("");
      t.add(row);
      o << "  " << (which == 0 ? "damping D [N s/m]" : "stiffness K [N/m]")
        << ": participant estimate [95 % interval]; last row mean (sample std) over participants\n"
        << t.str();
    }
    if (const auto b = method_bias_note(g.method); !b.empty()) o << "  ** " << g.method << " " << b << " **\n";
  }
  return o.str();
}

nlohmann::json group_json(const std::vector<GroupTable>& tables) {
  auto f = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json arr = nlohmann::json::array();
  for (const auto& g : tables) {
    nlohmann::json j = {{"method", g.method},
                        {"is_default", g.method == default_method()},
                        {"biased", !method_bias_note(g.method).empty()},
                        {"n_participants", g.n()},
                        {"std_ddof", 1},
                        {"configuration", g.configuration},
                        {"n_configurations", g.n_configurations},
                        {"configuration_text", g.configuration_text}};
    nlohmann::json el = nlohmann::json::object();
    for (int i = 0; i < 4; ++i) {
      el[element("D", i)] = {{"unit", "N s/m"}, {"mean", f(g.d_mean(i / 2, i % 2))}, {"std", f(g.d_std(i / 2, i % 2))}};
      el[element("K", i)] = {{"unit", "N/m"}, {"mean", f(g.k_mean(i / 2, i % 2))}, {"std", f(g.k_std(i / 2, i % 2))}};
    }
    j["elements"] = el;
    nlohmann::json ps = nlohmann::json::array();
    for (const auto& mem : g.members) {
      const auto& s = mem.session;
      nlohmann::json pe = nlohmann::json::object();
      for (int i = 0; i < 4; ++i) {
        const int r = i / 2, c = i % 2;
        pe[element("D", i)] = {{"unit", "N s/m"}, {"estimate", f(s.d_nspm(r, c))}, {"ci95_lo", f(s.d_lo(r, c))}, {"ci95_hi", f(s.d_hi(r, c))}};
        pe[element("K", i)] = {{"unit", "N/m"}, {"estimate", f(s.k_npm(r, c))}, {"ci95_lo", f(s.k_lo(r, c))}, {"ci95_hi", f(s.k_hi(r, c))}};
      }
      ps.push_back({{"participant_id", mem.participant}, {"log", mem.log}, {"identifiable", s.identifiable},
                    {"flag_reason", s.flag}, {"elements", pe}});
    }
    j["participants"] = ps;
    arr.push_back(j);
  }
  return {{"groups", arr}};
}

std::string group_csv(const std::vector<GroupTable>& tables) {
  std::ostringstream o;
  o << "level,participant_id,log,method,is_default,is_biased,configuration,parameter,quantity,row,col,unit,statistic,"
       "value_si,ci95_lo_si,ci95_hi_si,n_participants,identifiable,flag_reason\n";
  for (const auto& g : tables) {
    const std::string head = quote(g.method) + "," + (g.method == default_method() ? "true" : "false") + "," +
                             (method_bias_note(g.method).empty() ? "false" : "true") + "," + std::to_string(g.configuration);
    for (int i = 0; i < 8; ++i) {
      const bool d = i < 4;
      const int r = (i % 4) / 2, c = i % 2;
      const std::string el = element(d ? "D" : "K", i % 4);
      const std::string tail = el + "," + (d ? "damping" : "stiffness") + "," + std::to_string(r + 1) + "," +
                               std::to_string(c + 1) + "," + (d ? "N s/m" : "N/m");
      for (const auto& mem : g.members) {
        const auto& s = mem.session;
        o << "participant," << quote(mem.participant) << ',' << quote(mem.log) << ',' << head << ',' << tail << ",estimate,"
          << val(d ? s.d_nspm(r, c) : s.k_npm(r, c)) << ',' << val(d ? s.d_lo(r, c) : s.k_lo(r, c)) << ','
          << val(d ? s.d_hi(r, c) : s.k_hi(r, c)) << ',' << g.n() << ',' << (s.identifiable ? "true" : "false") << ','
          << quote(s.flag) << '\n';
      }
      o << "group,,," << head << ',' << tail << ",mean," << val(d ? g.d_mean(r, c) : g.k_mean(r, c)) << ",,," << g.n()
        << ",,\n";
      o << "group,,," << head << ',' << tail << ",std," << val(d ? g.d_std(r, c) : g.k_std(r, c)) << ",,," << g.n()
        << ",,\n";
    }
  }
  return o.str();
}

}  // namespace manip::estimation
