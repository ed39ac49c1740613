#include "x20ds1928/info_channels.hpp"

namespace ds1928 {
namespace {

// clang-format off
constexpr std::array<NamedInfo, 10> kNamedInfos{{
    {"diagnosis", 0x41, false, "diagnosis: function reserve (valuation numbers)"},
    {"position2_word1", 0x42, false, "position value 2, word 1 (bits 15..0)"},
    {"position2_word2", 0x43, false, "position value 2, word 2 (bits 31..16)"},
    {"position2_word3", 0x44, false, "position value 2, word 3 (bits 47..32)"},
    {"temperature1", 0x4C, false, "temperature 1 (encoder), 0.1 K"},
    {"temperature2", 0x4D, false, "temperature 2 (external sensor), 0.1 K"},
    {"commutation", 0x51, false, "commutation signals"},
    {"acceleration", 0x52, true, "acceleration (signed: an assumption, the sources give no format)"},
    {"error_sources", 0x59, false, "operating-status error sources"},
    {"timestamp", 0x5B, false, "time stamp"},
}};
// clang-format on

}  // namespace

std::string_view info_request_problem(const InfoRequest& r) noexcept {
  using namespace info_command;
  if (r.command == kReadParameter) {
    if (r.block) return "command 0x04 reads an unblocked parameter: no block";
    return {};
  }
  if (r.command == kReadBlockParameter) {
    if (!r.block) return "command 0x06 reads from a memory block: a block is needed";
    return {};
  }
  if (r.command >= kReadInfoWord1 && r.command <= kReadInfoWord4) {
    if (r.mrs < 0x40 || r.mrs > 0x5F || r.mrs == 0x4F || r.mrs == 0x5F)
      return "commands 0x08..0x0B read additional information: MRS code 0x40..0x5E (0x4F and "
             "0x5F stop it)";
    if (r.parameter != 0 || r.block)
      return "commands 0x08..0x0B take the MRS code only: no parameter or block";
    return {};
  }
  return "command must be 0x04, 0x06 or 0x08..0x0B (datasheet §11.8.3.1)";
}

std::span<const NamedInfo> named_infos() noexcept {
  return kNamedInfos;
}

const NamedInfo* find_named_info(std::string_view name) noexcept {
  for (const NamedInfo& n : kNamedInfos)
    if (n.name == name) return &n;
  return nullptr;
}

}  // namespace ds1928
