#include "control/request_parser.hpp"

namespace ds1928::control {

using json = nlohmann::json;

ParsedRequest parse_request(std::string_view line) {
  ParsedRequest out;
  auto reject = [&](ErrorCode code, std::string message) {
    out.error = code;
    out.message = std::move(message);
    return std::move(out);
  };
  try {
    out.body = json::parse(line);
  } catch (const json::exception& e) {
    // parse_error for bad syntax, out_of_range for a number beyond double: both are the
    // client's bad JSON. The library's "[json.exception.x.n] " prefix means nothing to a client.
    std::string what = e.what();
    if (const auto p = what.find("] "); p != std::string::npos) what.erase(0, p + 2);
    out.body = nullptr;
    return reject(ErrorCode::BadJson, std::move(what));
  }
  if (!out.body.is_object())
    return reject(ErrorCode::BadJson,
                  std::string("request must be a JSON object, got ") + out.body.type_name());
  if (const auto it = out.body.find("id"); it != out.body.end()) out.id = *it;
  const auto cmd = out.body.find("cmd");
  if (cmd == out.body.end())
    return reject(ErrorCode::BadArgument, "argument 'cmd' (string) is required");
  if (!cmd->is_string())
    return reject(ErrorCode::BadArgument,
                  std::string("argument 'cmd': expected string, got ") + cmd->type_name());
  out.command = cmd->get<std::string>();
  return out;
}

}  // namespace ds1928::control
