#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

std::string_view to_string(DataType t) noexcept {
  switch (t) {
    case DataType::USINT:
      return "USINT";
    case DataType::SINT:
      return "SINT";
    case DataType::UINT:
      return "UINT";
    case DataType::INT:
      return "INT";
    case DataType::UDINT:
      return "UDINT";
    case DataType::DINT:
      return "DINT";
  }
  return "?";
}

std::string_view to_string(RegisterDirection d) noexcept {
  switch (d) {
    case RegisterDirection::In:
      return "in";
    case RegisterDirection::Out:
      return "out";
    case RegisterDirection::Config:
      return "cfg";
    case RegisterDirection::Command:
      return "cmd";
    case RegisterDirection::ReadOnly:
      return "ro";
  }
  return "?";
}

std::string_view setting_key(Setting s) noexcept {
  switch (s) {
    case Setting::None:
      return "—";
    case Setting::AlwaysOne:
      return "— (always 1)";
    case Setting::EnDatMode:
      return "endat_enable, position_signed, fast_clock_off, sincos_unused";
    case Setting::Prescaler:
      return "prescaler";
    case Setting::SlframeGenId:
      return "slframe_gen_id";
    case Setting::ErrorEnable:
      return "error_enable";
    case Setting::VssMin:
      return "vss_min_mv";
    case Setting::VssMax:
      return "vss_max_mv";
    case Setting::QuitTime:
      return "quit_time_us";
    case Setting::OutputMtu:
      return "output_mtu";
    case Setting::InputMtu:
      return "input_mtu";
    case Setting::FlatstreamMode:
      return "flatstream_mode";
    case Setting::Forward:
      return "forward";
    case Setting::ForwardDelay:
      return "forward_delay_us";
  }
  return "?";
}

uint32_t setting_value(Setting s, const ModuleSettings& m) noexcept {
  switch (s) {
    case Setting::None:
      return 0;
    case Setting::AlwaysOne:
      return 1;
    case Setting::EnDatMode:
      return m.endat_mode();
    case Setting::Prescaler:
      return m.prescaler;
    case Setting::SlframeGenId:
      return m.slframe_gen_id;
    case Setting::ErrorEnable:
      return m.error_enable;
    case Setting::VssMin:
      return m.vss_min_mv;
    case Setting::VssMax:
      return m.vss_max_mv;
    case Setting::QuitTime:
      return m.quit_time_us;
    case Setting::OutputMtu:
      return m.output_mtu;
    case Setting::InputMtu:
      return m.input_mtu;
    case Setting::FlatstreamMode:
      return m.flatstream_mode;
    case Setting::Forward:
      return m.forward;
    case Setting::ForwardDelay:
      return m.forward_delay_us;
  }
  return 0;
}

std::array<RegisterWrite, kStartupWriteCount> startup_writes(
    const ModuleSettings& settings) noexcept {
  std::array<RegisterWrite, kStartupWriteCount> out{};
  for (const RegisterInfo& r : kObjectDictionary) {
    if (r.startup_order == 0 || r.startup_order > kStartupWriteCount) continue;
    out[r.startup_order - 1] = {r.number, r.size(), setting_value(r.setting, settings)};
  }
  return out;
}

}  // namespace ds1928
