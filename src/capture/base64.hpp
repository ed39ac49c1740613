// Base64 (RFC 4648, with padding): how capture bytes travel in the JSON lines of the control
// socket. Pure codec.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ds1928::capture {

[[nodiscard]] std::string base64_encode(std::span<const uint8_t> bytes);
// nullopt when `text` is not canonical padded base64.
[[nodiscard]] std::optional<std::vector<uint8_t>> base64_decode(std::string_view text);

}  // namespace ds1928::capture
