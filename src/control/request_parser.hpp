// First stage of every request line, before any handler runs: the line must be a JSON object
// with a string "cmd". Pure (no server, no socket), so unit tests and the fuzz harness call it
// directly; the server answers a rejection with `error` and `message`.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>

#include "control/control_server.hpp"

namespace ds1928::control {

struct ParsedRequest {
  nlohmann::json body;  // the whole request object (null when the line is not one)
  nlohmann::json id;    // "id" to echo in the reply; null when absent
  std::string command;  // "cmd"; empty when rejected
  std::optional<ErrorCode> error;
  std::string message;  // what was wrong, when rejected
};

// Never throws a JSON library error: whatever the line holds becomes a rejection.
[[nodiscard]] ParsedRequest parse_request(std::string_view line);

}  // namespace ds1928::control
