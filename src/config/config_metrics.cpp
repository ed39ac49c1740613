#include "config/config_metrics.hpp"

#include <arpa/inet.h>

#include <array>
#include <charconv>

namespace ds1928 {

std::optional<MetricsListen> parse_listen_address(std::string_view text) {
  const auto colon = text.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return std::nullopt;
  std::string_view host = text.substr(0, colon);
  const std::string_view port = text.substr(colon + 1);
  unsigned value = 0;
  const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
  if (port.empty() || ec != std::errc{} || end != port.data() + port.size() || value > 65535)
    return std::nullopt;
  const bool v6 = host.size() >= 2 && host.front() == '[' && host.back() == ']';
  if (v6) host = host.substr(1, host.size() - 2);
  const std::string h(host);
  std::array<unsigned char, 16> buf{};
  if (::inet_pton(v6 ? AF_INET6 : AF_INET, h.c_str(), buf.data()) != 1) return std::nullopt;
  return MetricsListen{h, static_cast<uint16_t>(value)};
}

void config_detail::parse_metrics(Section s, MetricsConfig& c) {
  std::string listen;
  if (s.text("listen", listen, 64)) {
    if (listen == "off") {
      c.listen.reset();
    } else if (auto l = parse_listen_address(listen)) {
      c.listen = *l;
    } else {
      s.error("listen", "'" + listen +
                            "' is neither 'off' nor an address 'IPv4:PORT' or '[IPv6]:PORT' "
                            "(e.g. 127.0.0.1:9928)");
    }
  }
  s.integer("max_connections", c.max_connections, 1, 1024);
  s.integer("timeout_ms", c.timeout_ms, 10, 600000, "ms");
  s.finish();
}

}  // namespace ds1928
