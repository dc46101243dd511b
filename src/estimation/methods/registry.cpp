#include "manip/estimation/methods/registry.hpp"

#include <stdexcept>

namespace manip::estimation {

// Built-in methods, one line each, in the order of --method all; each is
// defined in src/estimation/methods/<name>.cpp as make_<name>_method().
#define MANIP_BUILTIN_METHODS(X) \
  X(pem)                         \
  X(paper)                       \
  X(paper_pooled)                \
  X(oe)                          \
  X(oe_trial)                    \
  /* a new method: one line X(name) \ above this one */

#define MANIP_DECLARE(name) std::unique_ptr<Method> make_##name##_method();
MANIP_BUILTIN_METHODS(MANIP_DECLARE)
#undef MANIP_DECLARE

namespace {

std::vector<std::unique_ptr<Method>>& registry() {
  static std::vector<std::unique_ptr<Method>> r = [] {
    std::vector<std::unique_ptr<Method>> v;
#define MANIP_ADD(name) v.push_back(make_##name##_method());
    MANIP_BUILTIN_METHODS(MANIP_ADD)
#undef MANIP_ADD
    return v;
  }();
  return r;
}

}  // namespace

std::vector<const Method*> registered_methods() {
  std::vector<const Method*> out;
  for (const auto& m : registry()) out.push_back(m.get());
  return out;
}

const Method* find_method(std::string_view name) {
  for (const auto& m : registry())
    if (m->name() == name) return m.get();
  return nullptr;
}

std::vector<std::string> all_methods() {
  std::vector<std::string> out;
  for (const auto& m : registry()) out.push_back(m->name());
  return out;
}

std::string method_list() {
  std::string out;
  for (const auto& m : registry()) out += (out.empty() ? "" : ", ") + m->name();
  return out;
}

// Why pem and not the paper's estimator: docs/accuracy-study.md.
std::string default_method() { return "pem"; }

void register_method(std::unique_ptr<Method> m) {
  if (!m || m->name().empty()) throw std::invalid_argument("register_method: a method needs a name");
  if (m->name() == "all" || find_method(m->name()))
    throw std::invalid_argument("register_method: method name '" + m->name() + "' is taken");
  registry().push_back(std::move(m));
}

}  // namespace manip::estimation

namespace manip::estimation {

std::string method_bias_note(std::string_view name) {
  // docs/accuracy-study.md: the pooled paper estimator over 20 simulated sessions.
  if (name == "paper-pooled")
    return "BIASED: -68 % to +107 % off in the accuracy study; its narrow 95 % intervals cover the truth in 0-5 % of "
           "sessions (docs/accuracy-study.md)";
  return {};
}

}  // namespace manip::estimation
