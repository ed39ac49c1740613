#include "core/register_catalogue.hpp"

#include <algorithm>
#include <cstdio>

namespace ds1928 {
namespace {

using D = RegisterDirection;

// Cyclic registers: offsets from docs/powerlink.md §Process image (function model 0) and the
// datasheet's FM254 table (§11.3.2); configuration registers with their bus-controller defaults
// (§11.9.4.1) and start-up order; then the acyclic reads.
constexpr std::array<RegisterInfo, 38> kCatalogue{{
    // One register a row, as the datasheet lists them.
    // clang-format off
    // number count stride name size direction models default fm0 fm0_after can fm254_members order
    {4180, 1, 1, "PositionHW", 4, D::In, kBothModels, {}, 0, false, 0, 0, 0},
    {4188, 1, 1, "PositionLW", 4, D::In, kBothModels, {}, 4, false, 4, 0, 0},
    {4172, 1, 1, "PosTime", 4, D::In, kFm0, {}, 8, false, kNoOffset, 0, 0},
    {4163, 1, 1, "PosCycle", 1, D::In, kBothModels, {}, 12, false, 15, 0, 0},
    {683, 1, 1, "SDCLifeCount", 1, D::In, kFm0, {}, 13, false, kNoOffset, 0, 0},
    {261, 1, 1, "ErrorInfo", 1, D::In, kBothModels, {}, 14, false, 14, 0, 0},
    {4672, 1, 1, "InputSequence", 1, D::In, kBothModels, {}, 15, false, 8, 0, 0},
    {4673, 15, 1, "RxByte1..15", 1, D::In, kBothModels, {}, 16, false, 9, 5, 0},
    {4704, 1, 1, "OutputSequence", 1, D::Out, kBothModels, {}, 0, false, 0, 0, 0},
    {4705, 15, 1, "TxByte1..15", 1, D::Out, kBothModels, {}, 1, false, 1, 5, 0},
    {325, 1, 1, "AckErrorInfo", 1, D::Out, kBothModels, {}, 1, true, 6, 0, 0},
    {1025, 1, 1, "SinCosEnable", 1, D::Config, kBothModels, 1, kNoOffset, false, kNoOffset, 0, 1},
    {1027, 1, 1, "SinCosRefSource", 1, D::Config, kBothModels, 1, kNoOffset, false, kNoOffset, 0, 2},
    {654, 1, 1, "CfO_SystemCyclePrescaler", 2, D::Config, kBothModels, 2, kNoOffset, false, kNoOffset, 0, 3},
    {513, 1, 1, "CfO_SlframeGenID", 1, D::Config, kBothModels, 14, kNoOffset, false, kNoOffset, 0, 4},
    {389, 1, 1, "ErrorEnableID_1710", 1, D::Config, kBothModels, 255, kNoOffset, false, kNoOffset, 0, 5},
    {1034, 1, 1, "SinCosVssMin", 2, D::Config, kBothModels, 800, kNoOffset, false, kNoOffset, 0, 6},
    {1038, 1, 1, "SinCosVssMax", 2, D::Config, kBothModels, 1200, kNoOffset, false, kNoOffset, 0, 7},
    {1044, 1, 1, "SinCosQuitTime", 4, D::Config, kBothModels, 100000, kNoOffset, false, kNoOffset, 0, 8},
    {4609, 1, 1, "OutputMTU", 1, D::Config, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 9},
    {4611, 1, 1, "InputMTU", 1, D::Config, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 10},
    {4613, 1, 1, "FlatstreamMode", 1, D::Config, kBothModels, 0, kNoOffset, false, kNoOffset, 0, 11},
    {4615, 1, 1, "Forward", 1, D::Config, kBothModels, 1, kNoOffset, false, kNoOffset, 0, 12},
    {4620, 1, 1, "ForwardDelay", 2, D::Config, kBothModels, 0, kNoOffset, false, kNoOffset, 0, 13},
    {4097, 1, 1, "EnDatMode", 1, D::Config, kBothModels, 0, kNoOffset, false, kNoOffset, 0, 14},
    {4099, 1, 1, "EnDatAck", 1, D::Command, kBothModels, 0, kNoOffset, false, kNoOffset, 0, 0},
    {4868, 4, 8, "EnDatInfoCmd01..04", 4, D::Config, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4352, 1, 1, "EnDatError", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4353, 1, 1, "EnDatWarning", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4354, 2, 1, "OperatingStatus_02..03", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4356, 44, 1, "ParamManuf_04..47", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4400, 16, 1, "OperatingParam_00..15", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4417, 63, 1, "ParamManufEnDat22_01..63", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4935, 1, 1, "EnDatInfoOK", 1, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4994, 4, 16, "EnDatInfo01..04", 2, D::ReadOnly, kBothModels, {}, kNoOffset, false, kNoOffset, 0, 0},
    // Views of the same bits: documented for completeness, never addressed on their own.
    {4174, 1, 1, "PosTime (16 bit)", 2, D::In, kFm0, {}, kNoOffset, false, kNoOffset, 0, 0},
    {4188, 1, 1, "Position (DINT view of PositionLW)", 4, D::In, kFm0, {}, 4, false, kNoOffset, 0, 0},
    {0, 0, 1, "", 0, D::ReadOnly, 0, {}, kNoOffset, false, kNoOffset, 0, 0},
    // clang-format on
}};

// The real entries (the table's tail holds documentation-only rows and a terminator).
constexpr std::size_t kEntries = 35;

}  // namespace

std::string_view to_string(RegisterDirection d) noexcept {
  switch (d) {
    case D::In:
      return "in";
    case D::Out:
      return "out";
    case D::Config:
      return "cfg";
    case D::Command:
      return "cmd";
    case D::ReadOnly:
      return "ro";
  }
  return "?";
}

std::span<const RegisterInfo> register_catalogue() noexcept {
  return {kCatalogue.data(), kEntries};
}

const RegisterInfo* find_register(uint16_t reg) noexcept {
  for (const RegisterInfo& r : register_catalogue())
    if (r.contains(reg)) return &r;
  return nullptr;
}

std::optional<uint8_t> register_size(uint16_t reg) noexcept {
  if (const RegisterInfo* r = find_register(reg)) return r->size;
  return std::nullopt;
}

namespace {

[[nodiscard]] uint32_t setting_for(uint16_t reg, const ModuleSettings& s) noexcept {
  switch (reg) {
    case reg::kSinCosEnable:
    case reg::kSinCosRefSource:
      return 1;  // the datasheet: must always be 1
    case reg::kSystemCyclePrescaler:
      return s.prescaler;
    case reg::kSlframeGenId:
      return s.slframe_gen_id;
    case reg::kErrorEnable:
      return s.error_enable;
    case reg::kSinCosVssMin:
      return s.vss_min_mv;
    case reg::kSinCosVssMax:
      return s.vss_max_mv;
    case reg::kSinCosQuitTime:
      return s.quit_time_us;
    case reg::kOutputMtu:
      return s.output_mtu;
    case reg::kInputMtu:
      return s.input_mtu;
    case reg::kFlatstreamMode:
      return s.flatstream_mode;
    case reg::kForward:
      return s.forward;
    case reg::kForwardDelay:
      return s.forward_delay_us;
    case reg::kEnDatMode:
      return s.endat_mode();
    default:
      return 0;
  }
}

}  // namespace

std::array<RegisterWrite, kStartupWriteCount> startup_writes(
    const ModuleSettings& settings) noexcept {
  std::array<RegisterWrite, kStartupWriteCount> out{};
  for (const RegisterInfo& r : register_catalogue()) {
    if (r.startup_order == 0 || r.startup_order > kStartupWriteCount) continue;
    out[r.startup_order - 1] = {r.number, r.size, setting_for(r.number, settings)};
  }
  return out;
}

std::string catalogue_markdown() {
  std::string out =
      "| register | name | size | dir | FM0 | FM254 | bus-controller default | FM0 block offset | "
      "FM254 CAN offset | start-up order |\n"
      "|---|---|---|---|---|---|---|---|---|---|\n";
  char buf[64];
  for (const RegisterInfo& r : kCatalogue) {
    if (r.name.empty()) break;
    std::string number = std::to_string(r.number);
    if (r.count > 1) {
      const unsigned last = r.number + (r.count - 1U) * r.stride;
      number += "..";
      number += std::to_string(last);
      if (r.stride > 1) number += " step " + std::to_string(r.stride);
    }
    out += "| " + number + " | " + std::string(r.name) + " | " + std::to_string(r.size) + " | " +
           std::string(to_string(r.direction)) + " | " + ((r.models & kFm0) ? "yes" : "—") + " | ";
    if (r.models & kFm254)
      out += r.count > 1 && r.fm254_members ? std::to_string(r.fm254_members) + " members" : "yes";
    else
      out += "—";
    out += " | " + (r.default_value ? std::to_string(*r.default_value) : std::string("—")) + " | ";
    if (r.fm0_offset == kNoOffset || !(r.models & kFm0)) {
      out += "—";
    } else {
      std::snprintf(buf, sizeof buf, "%s %d%s", r.direction == D::In ? "PRes" : "PReq",
                    r.fm0_offset, r.fm0_after_tx_bytes ? " + OutputMTU" : "");
      out += buf;
    }
    out += " | ";
    if (r.can_offset == kNoOffset) {
      out += "—";
    } else {
      const int last = r.can_offset + (r.fm254_members ? r.fm254_members : 1) * r.size - 1;
      char span[16];
      if (last == r.can_offset)
        std::snprintf(span, sizeof span, "%d", last);
      else
        std::snprintf(span, sizeof span, "%d–%d", r.can_offset, last);
      if (r.direction == D::In)
        std::snprintf(buf, sizeof buf, "in %s (object %d)", span, r.can_offset / 8 + 1);
      else
        std::snprintf(buf, sizeof buf, "out %s", span);
      out += buf;
    }
    out += " | " + (r.startup_order ? std::to_string(r.startup_order) : std::string("—")) + " |\n";
  }
  return out;
}

}  // namespace ds1928
