// The bus kinds as the configuration knows them: one row each (config_bus_kinds.cpp) with what
// differs between them: the `bus:` word, the cycle period a bus starts from, the function model
// of its modules, node numbers, whether axes may be left out, the section it needs and the checks
// that need the whole document. The loader (config.cpp) asks the row instead of naming a kind, so
// a new bus is one row here, its section file (config_<kind>.cpp) and its factory in the daemon
// (daemon/bus_factory.cpp). Internal to src/config.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "config/config.hpp"
#include "config/config_reader.hpp"

namespace ds1928::config_detail {

struct PowerlinkSites;  // config_powerlink.hpp

// What a bus kind's checks see: the whole document, parsed, and where its parts were written.
struct BusDocument {
  Diagnostics& diag;
  const DaemonConfig& config;
  const YAML::Node& doc;
  const std::vector<AxisSite>& axes;
  bool section_present = false;  // the file has the bus' own section
  Loc section_at;                // where it is (where it would go when absent)
  const PowerlinkSites& powerlink;
};

// A configuration without axes.
enum class EmptyAxes : uint8_t {
  Allowed,     // valid as it is
  OneDefault,  // one axis with every default is added
  Refused,     // an error: the bus needs at least one
};

struct BusKindRules {
  BusKind kind;
  std::string_view name;  // the `bus:` word, also the name of its section
  // How datasheets and messages call its bus controllers ("POWERLINK"); empty: none.
  std::string_view controller;
  uint32_t default_period_us;  // cycle.period_us when the file does not give it
  // The function model every module behind it runs; nullopt: either (default 0).
  std::optional<FunctionModel> function_model;
  uint8_t max_node;                   // axes[].node is 1..max_node
  bool module_offsets;                // axes[].pres_offset / preq_offset mean something
  EmptyAxes empty_axes;               // when `axes` is empty or absent
  std::string_view needs;             // non-empty: the section is required; what it must give
  void (*check)(const BusDocument&);  // checks when this is the bus; nullptr: none
};

// Every bus kind, in the order the `bus:` words are listed in messages.
[[nodiscard]] std::span<const BusKindRules> bus_kinds() noexcept;
[[nodiscard]] const BusKindRules& bus_kind_rules(BusKind kind) noexcept;

}  // namespace ds1928::config_detail
