// axes[].info: the module's additional-information channels (x20ds1928/info_channels.hpp,
// docs/configuration.md §axes[].info).
#pragma once

#include "config/config.hpp"
#include "config/config_reader.hpp"

namespace ds1928::config_detail {

// Reads the list at `key` of the axis' section into a.info and a.module.info_cmd: each entry is a
// name of the table (`temperature1`) or a map with `name` and either `info` (a name of the table)
// or the raw request (`command`, `mrs`, `parameter`, `block`, `signed`).
void parse_info(Section& axis, std::string_view key, AxisConfig& a);

}  // namespace ds1928::config_detail
