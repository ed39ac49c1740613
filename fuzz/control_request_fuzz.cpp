// Control socket requests: one line as a client sends it, through the request parser and the
// typed argument accessors every command handler uses. Only ArgumentError may leave an
// accessor (the server answers it with bad_argument); any other exception is a crash here, as
// it would be in the daemon.
#include <string_view>

#include "control/request_parser.hpp"

using namespace ds1928::control;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view line(reinterpret_cast<const char*>(data), size);
  ParsedRequest parsed = parse_request(line);
  if (parsed.error) return 0;
  const Request request(parsed.command, parsed.body, PeerCredentials{});
  for (const auto& item : parsed.body.items()) {
    const std::string key = item.key();
    auto guarded = [&](auto&& get) {
      try {
        (void)get();
      } catch (const ArgumentError&) {
      }
    };
    guarded([&] { return request.opt_uint(key); });
    guarded([&] { return request.opt_uint(key, 0xFFFF); });
    guarded([&] { return request.opt_int(key); });
    guarded([&] { return request.opt_string(key); });
    guarded([&] { return request.opt_bool(key); });
    guarded([&] { return request.get_uint(key, 255); });
    (void)request.has(key);
    (void)item.value().dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  }
  return 0;
}
