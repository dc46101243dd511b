#pragma once
// The one list of estimation methods. Built-in methods are listed once in
// src/estimation/methods/registry.cpp (one line each); a program or test may
// add its own with register_method() / MethodRegistration before it
// estimates. Everything that lists methods (the CLI's --method and --help,
// the settings' `methods` key, `all`, docs) asks this registry.
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "manip/estimation/methods/method.hpp"

namespace manip::estimation {

// Registered methods in registration order (built-ins first).
std::vector<const Method*> registered_methods();
// nullptr if no method has this name.
const Method* find_method(std::string_view name);
// Names in registration order ("all" on the command line).
std::vector<std::string> all_methods();
// "pem, paper, ..." for messages.
std::string method_list();
// The method run when none is chosen.
std::string default_method();
// Non-empty for a method known to be biased (shown wherever its results are).
std::string method_bias_note(std::string_view name);

// Adds a method; throws std::invalid_argument if its name is taken or empty.
// Not thread-safe: register at start-up (or from a static MethodRegistration).
void register_method(std::unique_ptr<Method> m);

struct MethodRegistration {
  explicit MethodRegistration(std::unique_ptr<Method> m) { register_method(std::move(m)); }
};

}  // namespace manip::estimation
