#pragma once
// The bus configuration's error lines, shared by the configuration tests.
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "manip/canopen/config.hpp"

namespace canopen_test {

// parse_config must refuse `text`; its messages, each also shown on failure.
inline std::vector<std::string> errors_of(const std::string& text) {
  manip::canopen::CanConfig c;
  std::vector<std::string> e;
  CHECK_FALSE(manip::canopen::parse_config(text, "bus.yml", c, e));
  for (const auto& s : e) UNSCOPED_INFO(s);
  return e;
}

inline bool has(const std::vector<std::string>& es, const std::string& s) {
  for (const auto& e : es)
    if (e == s) return true;
  return false;
}

}  // namespace canopen_test
