// The X20DS1928's object dictionary: every register of the module in one constexpr table
// (datasheet 002 §11, X20DS1928.md §2–§6) — number, name, data type, access per function model,
// where function model 0 puts a cyclic register in the POWERLINK module block and function model
// 254 in the CAN objects, its default SDO subindex on a bus controller, its bus-controller
// default, the values the module accepts, the setting (ModuleSettings, YAML key) it carries and
// the order in which a master writes it at start. Everything else derives from this table: the
// named register numbers and cyclic offsets below, the POWERLINK process image, the CAN-I/O
// object codec, the SDO mapping of both buses, the start-up configuration, both simulators and
// docs/registers.md. No other file states a register number.
// Pure: constexpr data and lookups, no allocation (markdown rendering aside).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "x20ds1928/module_image.hpp"
#include "x20ds1928/module_settings.hpp"

namespace ds1928 {

// IEC 61131 types of the datasheet.
enum class DataType : uint8_t { USINT, SINT, UINT, INT, UDINT, DINT };
[[nodiscard]] constexpr uint8_t size_of(DataType t) noexcept {
  switch (t) {
    case DataType::USINT:
    case DataType::SINT:
      return 1;
    case DataType::UINT:
    case DataType::INT:
      return 2;
    case DataType::UDINT:
    case DataType::DINT:
      return 4;
  }
  return 0;
}
[[nodiscard]] std::string_view to_string(DataType t) noexcept;

enum class RegisterDirection : uint8_t {
  In,        // cyclic, module → master
  Out,       // cyclic, master → module
  Config,    // acyclic, written by the master (configuration)
  Command,   // acyclic write, self-clearing (EnDatAck)
  ReadOnly,  // acyclic read (identification, status)
};
[[nodiscard]] std::string_view to_string(RegisterDirection d) noexcept;

// Function models a register exists in (its access is `direction` in each of them).
enum ModelMask : uint8_t { kFm0 = 1, kFm254 = 2, kBothModels = 3 };

// The setting a configuration register carries: the ModuleSettings field (YAML
// `axes[].module.<key>`) its start-up value comes from.
enum class Setting : uint8_t {
  None,
  AlwaysOne,  // the datasheet: must always be 1
  EnDatMode,  // endat_enable, position_signed, fast_clock_off, sincos_unused
  Prescaler,
  SlframeGenId,
  ErrorEnable,
  VssMin,
  VssMax,
  QuitTime,
  OutputMtu,
  InputMtu,
  FlatstreamMode,
  Forward,
  ForwardDelay,
};
// The YAML key(s) under axes[].module, or "—".
[[nodiscard]] std::string_view setting_key(Setting s) noexcept;
// The register value `s` asks for under `settings`.
[[nodiscard]] uint32_t setting_value(Setting s, const ModuleSettings& settings) noexcept;
// Settings that reconfigure the Flatstream channel when written.
[[nodiscard]] constexpr bool is_flatstream_setting(Setting s) noexcept {
  return s == Setting::OutputMtu || s == Setting::InputMtu || s == Setting::FlatstreamMode ||
         s == Setting::Forward || s == Setting::ForwardDelay;
}

inline constexpr int8_t kNoOffset = -1;

// Values a register accepts (inclusive).
struct ValueRange {
  uint32_t min = 0;
  uint32_t max = 0;
  [[nodiscard]] constexpr bool contains(uint32_t v) const noexcept { return v >= min && v <= max; }
};

struct RegisterInfo {
  uint16_t number = 0;  // datasheet register number of the first member
  uint8_t count = 1;    // family members (RxByte1..15: 15)
  uint8_t stride = 1;   // register-number step between members
  std::string_view name{};
  DataType type = DataType::USINT;
  RegisterDirection direction = RegisterDirection::ReadOnly;
  uint8_t models = kBothModels;
  // A second reading of bits another register carries (Position = PositionLW read signed):
  // documented, never addressed on its own, left out of every lookup.
  bool view = false;
  std::optional<uint32_t> default_value{};  // bus-controller default (datasheet §11.9.4.1)
  std::optional<ValueRange> range{};        // writes accepted; none: the type's whole range
  std::optional<ValueRange> fm254_range{};  // when function model 254 accepts other values
  // Function model 0, POWERLINK: byte offset inside the module's PRes (In) or PReq (Out) block;
  // for a family the first member's. AckErrorInfo follows the Tx bytes: offset + OutputMTU.
  int8_t fm0_offset = kNoOffset;
  bool fm0_after_tx_bytes = false;
  // Function model 254, CAN-I/O: the datasheet's offset inside the CAN objects — inputs 0..15
  // across the two 8-byte input objects, outputs 0..7 in the output object.
  int8_t can_offset = kNoOffset;
  uint8_t fm254_members = 0;  // family members under function model 254 (0 = count)
  // Default SDO object on a bus controller: index 0x2000 + slot, this subindex for the first
  // member, the next ones for the following members (0 = no object).
  uint8_t sdo_subindex = 0;
  Setting setting = Setting::None;
  uint8_t startup_order = 0;  // 1.. = written at start in this order; 0 = not written

  [[nodiscard]] constexpr uint8_t size() const noexcept { return size_of(type); }
  [[nodiscard]] constexpr bool cyclic() const noexcept {
    return direction == RegisterDirection::In || direction == RegisterDirection::Out;
  }
  [[nodiscard]] constexpr bool in_model(FunctionModel fm) const noexcept {
    return (models & (fm == FunctionModel::Standard ? kFm0 : kFm254)) != 0;
  }
  [[nodiscard]] constexpr bool contains(uint16_t reg) const noexcept {
    return reg >= number && reg < number + count * stride && (reg - number) % stride == 0;
  }
  // Index of `reg` in the family (contains(reg) assumed).
  [[nodiscard]] constexpr unsigned member(uint16_t reg) const noexcept {
    return static_cast<unsigned>(reg - number) / stride;
  }
  [[nodiscard]] constexpr uint16_t last() const noexcept {
    return static_cast<uint16_t>(number + (count - 1) * stride);
  }
  [[nodiscard]] constexpr uint8_t members(FunctionModel fm) const noexcept {
    return fm == FunctionModel::BusController && fm254_members != 0 ? fm254_members : count;
  }
  [[nodiscard]] constexpr ValueRange accepts(FunctionModel fm) const noexcept {
    if (fm == FunctionModel::BusController && fm254_range) return *fm254_range;
    if (range) return *range;
    const uint8_t bits = static_cast<uint8_t>(8 * size());
    return {0, bits >= 32 ? 0xFFFF'FFFFu : (1u << bits) - 1u};
  }
};

namespace od_detail {
using D = RegisterDirection;
using T = DataType;
using S = Setting;
}  // namespace od_detail

// The table, in datasheet order: cyclic registers, configuration (start-up order), then the
// acyclic reads, then the views. Offsets of function model 0: docs/powerlink.md §Process image;
// of function model 254: the datasheet's table (§11.3.2); defaults: §11.9.4.1; MTU bounds: §11.3
// (5 Rx/Tx bytes on CAN) and §11.9.4.1.1 (a sequence needs 3 bytes).
// clang-format off
inline constexpr std::array<RegisterInfo, 37> kObjectDictionary{{
    {.number = 4180, .name = "PositionHW", .type = od_detail::T::UDINT, .direction = od_detail::D::In, .fm0_offset = 0, .can_offset = 0},
    {.number = 4188, .name = "PositionLW", .type = od_detail::T::UDINT, .direction = od_detail::D::In, .fm0_offset = 4, .can_offset = 4},
    {.number = 4172, .name = "PosTime", .type = od_detail::T::DINT, .direction = od_detail::D::In, .models = kFm0, .fm0_offset = 8},
    {.number = 4163, .name = "PosCycle", .type = od_detail::T::SINT, .direction = od_detail::D::In, .fm0_offset = 12, .can_offset = 15},
    {.number = 683, .name = "SDCLifeCount", .type = od_detail::T::SINT, .direction = od_detail::D::In, .models = kFm0, .fm0_offset = 13},
    {.number = 261, .name = "ErrorInfo", .direction = od_detail::D::In, .fm0_offset = 14, .can_offset = 14, .sdo_subindex = 0x10},
    {.number = 4672, .name = "InputSequence", .direction = od_detail::D::In, .fm0_offset = 15, .can_offset = 8},
    {.number = 4673, .count = 15, .name = "RxByte1..15", .direction = od_detail::D::In, .fm0_offset = 16, .can_offset = 9, .fm254_members = 5},
    {.number = 4704, .name = "OutputSequence", .direction = od_detail::D::Out, .fm0_offset = 0, .can_offset = 0},
    {.number = 4705, .count = 15, .name = "TxByte1..15", .direction = od_detail::D::Out, .fm0_offset = 1, .can_offset = 1, .fm254_members = 5},
    {.number = 325, .name = "AckErrorInfo", .direction = od_detail::D::Out, .fm0_offset = 1, .fm0_after_tx_bytes = true, .can_offset = 6, .sdo_subindex = 0x11},
    {.number = 1025, .name = "SinCosEnable", .direction = od_detail::D::Config, .default_value = 1, .range = ValueRange{1, 1}, .sdo_subindex = 0x05, .setting = od_detail::S::AlwaysOne, .startup_order = 1},
    {.number = 1027, .name = "SinCosRefSource", .direction = od_detail::D::Config, .default_value = 1, .range = ValueRange{1, 1}, .sdo_subindex = 0x06, .setting = od_detail::S::AlwaysOne, .startup_order = 2},
    {.number = 654, .name = "CfO_SystemCyclePrescaler", .type = od_detail::T::UINT, .direction = od_detail::D::Config, .default_value = 2, .range = ValueRange{2, 0xFFFF}, .sdo_subindex = 0x02, .setting = od_detail::S::Prescaler, .startup_order = 3},
    {.number = 513, .name = "CfO_SlframeGenID", .direction = od_detail::D::Config, .default_value = 14, .sdo_subindex = 0x03, .setting = od_detail::S::SlframeGenId, .startup_order = 4},
    {.number = 389, .name = "ErrorEnableID_1710", .direction = od_detail::D::Config, .default_value = 255, .sdo_subindex = 0x04, .setting = od_detail::S::ErrorEnable, .startup_order = 5},
    {.number = 1034, .name = "SinCosVssMin", .type = od_detail::T::UINT, .direction = od_detail::D::Config, .default_value = 800, .range = ValueRange{0, 1500}, .sdo_subindex = 0x07, .setting = od_detail::S::VssMin, .startup_order = 6},
    {.number = 1038, .name = "SinCosVssMax", .type = od_detail::T::UINT, .direction = od_detail::D::Config, .default_value = 1200, .range = ValueRange{0, 1500}, .sdo_subindex = 0x08, .setting = od_detail::S::VssMax, .startup_order = 7},
    {.number = 1044, .name = "SinCosQuitTime", .type = od_detail::T::UDINT, .direction = od_detail::D::Config, .default_value = 100000, .range = ValueRange{0, 20'000'000}, .sdo_subindex = 0x09, .setting = od_detail::S::QuitTime, .startup_order = 8},
    {.number = 4609, .name = "OutputMTU", .direction = od_detail::D::Config, .range = ValueRange{2, 15}, .fm254_range = ValueRange{3, 5}, .sdo_subindex = 0x0A, .setting = od_detail::S::OutputMtu, .startup_order = 9},
    {.number = 4611, .name = "InputMTU", .direction = od_detail::D::Config, .range = ValueRange{2, 15}, .fm254_range = ValueRange{3, 5}, .sdo_subindex = 0x0B, .setting = od_detail::S::InputMtu, .startup_order = 10},
    {.number = 4613, .name = "FlatstreamMode", .direction = od_detail::D::Config, .default_value = 0, .range = ValueRange{0, 3}, .sdo_subindex = 0x0C, .setting = od_detail::S::FlatstreamMode, .startup_order = 11},
    {.number = 4615, .name = "Forward", .direction = od_detail::D::Config, .default_value = 1, .range = ValueRange{1, 7}, .sdo_subindex = 0x0D, .setting = od_detail::S::Forward, .startup_order = 12},
    {.number = 4620, .name = "ForwardDelay", .type = od_detail::T::UINT, .direction = od_detail::D::Config, .default_value = 0, .sdo_subindex = 0x0E, .setting = od_detail::S::ForwardDelay, .startup_order = 13},
    {.number = 4097, .name = "EnDatMode", .direction = od_detail::D::Config, .default_value = 0, .range = ValueRange{0, 0x0F}, .sdo_subindex = 0x01, .setting = od_detail::S::EnDatMode, .startup_order = 14},
    {.number = 4099, .name = "EnDatAck", .direction = od_detail::D::Command, .default_value = 0, .range = ValueRange{0, 0x03}, .sdo_subindex = 0x0F},
    {.number = 4868, .count = 4, .stride = 8, .name = "EnDatInfoCmd01..04", .type = od_detail::T::UDINT, .direction = od_detail::D::Config, .sdo_subindex = 0x12},
    {.number = 4352, .name = "EnDatError", .type = od_detail::T::UINT, .sdo_subindex = 0x20},
    {.number = 4353, .name = "EnDatWarning", .type = od_detail::T::UINT, .sdo_subindex = 0x21},
    {.number = 4354, .count = 2, .name = "OperatingStatus_02..03", .type = od_detail::T::UINT, .sdo_subindex = 0x22},
    {.number = 4356, .count = 44, .name = "ParamManuf_04..47", .type = od_detail::T::UINT, .sdo_subindex = 0x24},
    {.number = 4400, .count = 16, .name = "OperatingParam_00..15", .type = od_detail::T::UINT, .sdo_subindex = 0x50},
    {.number = 4417, .count = 63, .name = "ParamManufEnDat22_01..63", .type = od_detail::T::UINT, .sdo_subindex = 0x61},
    {.number = 4935, .name = "EnDatInfoOK", .sdo_subindex = 0x16},
    {.number = 4994, .count = 4, .stride = 16, .name = "EnDatInfo01..04", .type = od_detail::T::UINT, .sdo_subindex = 0x17},
    {.number = 4174, .name = "PosTime (16 bit)", .type = od_detail::T::INT, .direction = od_detail::D::In, .models = kFm0, .view = true},
    {.number = 4188, .name = "Position (DINT view of PositionLW)", .type = od_detail::T::DINT, .direction = od_detail::D::In, .models = kFm0, .view = true, .fm0_offset = 4},
}};
// clang-format on

[[nodiscard]] constexpr std::span<const RegisterInfo> object_dictionary() noexcept {
  return kObjectDictionary;
}

// The entry holding `reg` (a family member too; views never), or nullptr.
[[nodiscard]] constexpr const RegisterInfo* find_register(uint16_t reg) noexcept {
  for (const RegisterInfo& r : kObjectDictionary)
    if (!r.view && r.contains(reg)) return &r;
  return nullptr;
}
// The size in bytes of `reg`, nullopt when the dictionary does not know it.
[[nodiscard]] constexpr std::optional<uint8_t> register_size(uint16_t reg) noexcept {
  if (const RegisterInfo* r = find_register(reg)) return r->size();
  return std::nullopt;
}
// Position of `r` in kObjectDictionary (per-register storage, e.g. the simulated module's).
[[nodiscard]] constexpr std::size_t od_index(const RegisterInfo& r) noexcept {
  return static_cast<std::size_t>(&r - kObjectDictionary.data());
}

// The register a module setting is written to; a setting no register carries does not compile.
// The configuration takes the values it accepts for the setting from here (accepts()).
[[nodiscard]] consteval const RegisterInfo& setting_register(Setting s) {
  for (const RegisterInfo& r : kObjectDictionary)
    if (!r.view && r.setting == s) return r;
  throw "no register carries this setting";
}
// Compile-time lookup by the table's name; an unknown name does not compile.
[[nodiscard]] consteval const RegisterInfo& od_entry(std::string_view name) {
  for (const RegisterInfo& r : kObjectDictionary)
    if (r.name == name) return r;
  throw "no register of this name in kObjectDictionary";
}
[[nodiscard]] consteval std::size_t fm0_offset_of(std::string_view name) {
  const RegisterInfo& r = od_entry(name);
  if (r.fm0_offset == kNoOffset) throw "register without a function model 0 offset";
  return static_cast<std::size_t>(r.fm0_offset);
}
[[nodiscard]] consteval std::size_t can_offset_of(std::string_view name) {
  const RegisterInfo& r = od_entry(name);
  if (r.can_offset == kNoOffset) throw "register without a function model 254 offset";
  return static_cast<std::size_t>(r.can_offset);
}

// Register numbers by name, as the code addresses them.
namespace reg {
inline constexpr uint16_t kErrorInfo = od_entry("ErrorInfo").number;
inline constexpr uint16_t kAckErrorInfo = od_entry("AckErrorInfo").number;
inline constexpr uint16_t kSlframeGenId = od_entry("CfO_SlframeGenID").number;
inline constexpr uint16_t kSystemCyclePrescaler = od_entry("CfO_SystemCyclePrescaler").number;
inline constexpr uint16_t kErrorEnable = od_entry("ErrorEnableID_1710").number;
inline constexpr uint16_t kSinCosEnable = od_entry("SinCosEnable").number;
inline constexpr uint16_t kSinCosRefSource = od_entry("SinCosRefSource").number;
inline constexpr uint16_t kSinCosVssMin = od_entry("SinCosVssMin").number;
inline constexpr uint16_t kSinCosVssMax = od_entry("SinCosVssMax").number;
inline constexpr uint16_t kSinCosQuitTime = od_entry("SinCosQuitTime").number;
inline constexpr uint16_t kEnDatMode = od_entry("EnDatMode").number;
inline constexpr uint16_t kEnDatAck = od_entry("EnDatAck").number;
inline constexpr uint16_t kOutputMtu = od_entry("OutputMTU").number;
inline constexpr uint16_t kInputMtu = od_entry("InputMTU").number;
inline constexpr uint16_t kFlatstreamMode = od_entry("FlatstreamMode").number;
inline constexpr uint16_t kForward = od_entry("Forward").number;
inline constexpr uint16_t kForwardDelay = od_entry("ForwardDelay").number;
inline constexpr uint16_t kEnDatInfoCmd01 = od_entry("EnDatInfoCmd01..04").number;
inline constexpr uint16_t kEnDatInfoOk = od_entry("EnDatInfoOK").number;
inline constexpr uint16_t kEnDatInfo01 = od_entry("EnDatInfo01..04").number;
inline constexpr uint16_t kEnDatError = od_entry("EnDatError").number;
inline constexpr uint16_t kEnDatWarning = od_entry("EnDatWarning").number;
// The identification families, numbered as the datasheet names their members: member N of
// OperatingStatus_N / ParamManuf_N sits at kOperatingStatus0 + N (one run, N = 0..47),
// OperatingParam_N at kOperatingParam0 + N, ParamManufEnDat22_N at kParamManufEnDat22_0 + N.
inline constexpr uint16_t kOperatingStatus0 = kEnDatError;
inline constexpr uint16_t kOperatingStatus2 = od_entry("OperatingStatus_02..03").number;
inline constexpr uint16_t kParamManuf4 = od_entry("ParamManuf_04..47").number;
inline constexpr uint16_t kParamManuf0 = kOperatingStatus0;
inline constexpr uint16_t kOperatingParam0 = od_entry("OperatingParam_00..15").number;
inline constexpr uint16_t kParamManufEnDat22_1 = od_entry("ParamManufEnDat22_01..63").number;
inline constexpr uint16_t kParamManufEnDat22_0 = kParamManufEnDat22_1 - 1;
static_assert(kParamManuf4 == kParamManuf0 + 4 && kOperatingStatus2 == kOperatingStatus0 + 2);
}  // namespace reg

// Offsets the cyclic codecs use, taken from the table.
namespace fm0 {  // PRes block; PReq block (AckErrorInfo after the Tx bytes)
inline constexpr std::size_t kPositionHw = fm0_offset_of("PositionHW");
inline constexpr std::size_t kPositionLw = fm0_offset_of("PositionLW");
inline constexpr std::size_t kPosTime = fm0_offset_of("PosTime");
inline constexpr std::size_t kPosCycle = fm0_offset_of("PosCycle");
inline constexpr std::size_t kSdcLifeCount = fm0_offset_of("SDCLifeCount");
inline constexpr std::size_t kErrorInfo = fm0_offset_of("ErrorInfo");
inline constexpr std::size_t kInputSequence = fm0_offset_of("InputSequence");
inline constexpr std::size_t kRxBytes = fm0_offset_of("RxByte1..15");
inline constexpr std::size_t kOutputSequence = fm0_offset_of("OutputSequence");
inline constexpr std::size_t kTxBytes = fm0_offset_of("TxByte1..15");
inline constexpr std::size_t kMaxMtu = od_entry("RxByte1..15").count;
static_assert(od_entry("AckErrorInfo").fm0_after_tx_bytes &&
              fm0_offset_of("AckErrorInfo") == kTxBytes);
}  // namespace fm0
namespace fm254 {  // over the two input objects; in the output object
inline constexpr std::size_t kPositionHw = can_offset_of("PositionHW");
inline constexpr std::size_t kPositionLw = can_offset_of("PositionLW");
inline constexpr std::size_t kInputSequence = can_offset_of("InputSequence");
inline constexpr std::size_t kRxBytes = can_offset_of("RxByte1..15");
inline constexpr std::size_t kErrorInfo = can_offset_of("ErrorInfo");
inline constexpr std::size_t kPosCycle = can_offset_of("PosCycle");
inline constexpr std::size_t kOutputSequence = can_offset_of("OutputSequence");
inline constexpr std::size_t kTxBytes = can_offset_of("TxByte1..15");
inline constexpr std::size_t kAckErrorInfo = can_offset_of("AckErrorInfo");
inline constexpr std::size_t kMaxMtu = od_entry("RxByte1..15").fm254_members;
static_assert(kMaxMtu == od_entry("TxByte1..15").fm254_members);
}  // namespace fm254

// One acyclic write of the start-up configuration.
struct RegisterWrite {
  uint16_t reg = 0;
  uint8_t size = 1;
  uint32_t value = 0;
};
[[nodiscard]] consteval std::size_t startup_write_count() {
  std::size_t n = 0;
  for (const RegisterInfo& r : kObjectDictionary)
    if (r.startup_order != 0) ++n;
  return n;
}
inline constexpr std::size_t kStartupWriteCount = startup_write_count();
// The configuration a master writes at start, in the table's start-up order (EnDatMode last:
// the encoder is enabled once everything else is set).
[[nodiscard]] std::array<RegisterWrite, kStartupWriteCount> startup_writes(
    const ModuleSettings& settings) noexcept;

// The additional-information channels a master writes after the start-up configuration:
// EnDatInfoCmd0N for each configured channel (ModuleSettings::info_cmd ≠ 0), in channel order.
// Channels left off keep the module's default 0 and are not written.
struct InfoCommandWrites {
  std::array<RegisterWrite, 4> writes{};
  std::size_t count = 0;
  // Lvalues only: a span of a temporary (`for (w : info_command_writes(s).span())`) would dangle
  // before the loop's first iteration.
  [[nodiscard]] std::span<const RegisterWrite> span() const& noexcept {
    return {writes.data(), count};
  }
  std::span<const RegisterWrite> span() const&& = delete;
};
[[nodiscard]] constexpr InfoCommandWrites info_command_writes(const ModuleSettings& s) noexcept {
  constexpr const RegisterInfo& r = od_entry("EnDatInfoCmd01..04");
  static_assert(r.count == std::tuple_size_v<decltype(ModuleSettings::info_cmd)>);
  InfoCommandWrites out;
  for (std::size_t i = 0; i < r.count; ++i)
    if (s.info_cmd[i] != 0)
      out.writes[out.count++] = {static_cast<uint16_t>(r.number + i * r.stride), r.size(),
                                 s.info_cmd[i]};
  return out;
}

// The table as the Markdown of docs/registers.md (between its markers).
[[nodiscard]] std::string object_dictionary_markdown();

}  // namespace ds1928
