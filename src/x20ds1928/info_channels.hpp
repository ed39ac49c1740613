// The module's four additional-information channels (datasheet §11.8.3, X20DS1928.md §6): what
// EnDatInfoCmd01..04 asks the encoder for, and the named EnDat 2.2 additional information a
// configuration may ask for by name (axes[].info). The channel's value arrives in EnDatInfo0N
// (UINT, or INT for a signed parameter) while EnDatInfoOK bit N-1 says it is valid.
// Pure: constexpr data and the register's bit layout, no allocation.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace ds1928 {

inline constexpr std::size_t kInfoChannels = 4;

// The commands EnDatInfoCmd accepts (§11.8.3.1): the EnDat 2.1 parameter reads (0x04 unblocked,
// 0x06 from a memory block) and the EnDat 2.2 reads of word 1..4 of additional information
// (0x08..0x0B, MRS code only).
namespace info_command {
inline constexpr uint8_t kReadParameter = 0x04;
inline constexpr uint8_t kReadBlockParameter = 0x06;
inline constexpr uint8_t kReadInfoWord1 = 0x08;
inline constexpr uint8_t kReadInfoWord4 = 0x0B;
}  // namespace info_command

// One channel's request, as EnDatInfoCmd0N carries it.
struct InfoRequest {
  uint8_t command = 0;  // 0: the channel is off
  uint8_t mrs = 0;      // MRS code of the memory area / additional information
  uint8_t parameter = 0;
  std::optional<uint8_t> block;  // blocked areas (command 0x06)

  friend constexpr bool operator==(const InfoRequest&, const InfoRequest&) = default;
};

// EnDatInfoCmd0N's bit layout (§11.8.3.1): bits 0–7 command, 8–15 MRS code; unblocked: 16–23
// parameter number; blocked: 16–23 block number, 24–31 parameter number.
[[nodiscard]] constexpr uint32_t encode_info_command(const InfoRequest& r) noexcept {
  const uint32_t base = uint32_t{r.command} | uint32_t{r.mrs} << 8;
  if (r.block) return base | uint32_t{*r.block} << 16 | uint32_t{r.parameter} << 24;
  return base | uint32_t{r.parameter} << 16;
}
// The request a register value carries; `blocked` says which layout (the register itself does
// not: the command does — 0x06 reads from a block).
[[nodiscard]] constexpr InfoRequest decode_info_command(uint32_t v) noexcept {
  InfoRequest r;
  r.command = static_cast<uint8_t>(v);
  r.mrs = static_cast<uint8_t>(v >> 8);
  if (r.command == info_command::kReadBlockParameter) {
    r.block = static_cast<uint8_t>(v >> 16);
    r.parameter = static_cast<uint8_t>(v >> 24);
  } else {
    r.parameter = static_cast<uint8_t>(v >> 16);
  }
  return r;
}

// Why a request is not one the module can serve, or empty: the command is not one of §11.8.3.1,
// an EnDat 2.2 read names an MRS code outside additional information 1/2 (0x40–0x5F) or carries
// a parameter or block, a 0x04 read carries a block, a 0x06 read lacks one.
[[nodiscard]] std::string_view info_request_problem(const InfoRequest& r) noexcept;

// Common EnDat 2.2 additional information by name. Source: the EnDat 2.2 MRS codes of additional
// information 1 (0x40–0x4F) and 2 (0x50–0x5F), X20DS1928.md/endat.md §MRS codes; temperatures in
// 0.1 K (°C = raw × 0.1 − 273.2).
struct NamedInfo {
  std::string_view name;  // the configuration's word and the channel's default name
  uint8_t mrs;
  bool is_signed;            // read EnDatInfo0N as INT
  std::string_view meaning;  // docs/configuration.md
};
[[nodiscard]] std::span<const NamedInfo> named_infos() noexcept;
[[nodiscard]] const NamedInfo* find_named_info(std::string_view name) noexcept;
// The request for a named information: word 1 of its additional information.
[[nodiscard]] constexpr InfoRequest named_info_request(const NamedInfo& n) noexcept {
  return {info_command::kReadInfoWord1, n.mrs, 0, std::nullopt};
}

}  // namespace ds1928
