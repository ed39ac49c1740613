// The `metrics` section: where the OpenMetrics endpoint listens (docs/operations.md).
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "config/config.hpp"
#include "config/config_reader.hpp"

namespace ds1928 {

// "HOST:PORT" with an IPv4 literal or a bracketed IPv6 literal ("[::1]:9928"); nullopt when the
// text is neither (and not "off", which the caller handles).
[[nodiscard]] std::optional<MetricsListen> parse_listen_address(std::string_view text);

namespace config_detail {
void parse_metrics(Section s, MetricsConfig& c);
}  // namespace config_detail

}  // namespace ds1928
