// Configuration loader on any YAML text: either a configuration that dumps and loads back to
// the same dump, or errors that each say where and what.
#include <cstdlib>
#include <string_view>

#include "config/config_loader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto result = ds1928::load_config_from_string(text, "fuzz.yaml");
  if (result.ok()) {
    const std::string dumped = ds1928::dump_config(result.config());
    auto again = ds1928::load_config_from_string(dumped, "fuzz.yaml");
    if (!again.ok() || ds1928::dump_config(again.config()) != dumped) std::abort();
  } else {
    if (result.errors().empty()) std::abort();
    for (const auto& e : result.errors())
      if (e.message.empty()) std::abort();
    (void)result.error_report();
  }
  return 0;
}
