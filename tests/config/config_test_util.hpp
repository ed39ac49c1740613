// Helpers of the configuration tests: a YAML text loaded as a file named `name`, its one error,
// and bytes little-endian as a concise DCF stores them.
#pragma once

#include <catch2/catch.hpp>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "config/config_loader.hpp"

namespace ds1928::test {

inline ConfigResult from(std::string_view text, const std::string& name = "test.yaml") {
  return load_config_from_string(text, name);
}

// The single error the text is refused with (fails when there is none or more than one).
inline std::string one_error(std::string_view text, const std::string& name = "test.yaml") {
  const ConfigResult r = from(text, name);
  INFO(r.error_report());
  REQUIRE(r.errors().size() == 1);
  return r.errors().front().to_string();
}

// `v` as `n` bytes, least significant first.
inline std::vector<uint8_t> le(uint64_t v, int n) {
  std::vector<uint8_t> d;
  for (int i = 0; i < n; ++i) d.push_back(static_cast<uint8_t>(v >> (8 * i)));
  return d;
}

}  // namespace ds1928::test
