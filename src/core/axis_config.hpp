// One configured axis: which module on which bus node it is and how the module is set up. Every
// bus driver, the simulators and the daemon's EnDat service read it; the configuration (`axes:`)
// fills it.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "x20ds1928/error_bits.hpp"
#include "x20ds1928/info_channels.hpp"
#include "x20ds1928/module_image.hpp"
#include "x20ds1928/module_settings.hpp"

namespace ds1928 {

// The encoder expected behind a module (EnDat identification, docs/configuration.md
// §axes[].expected_encoder). An empty field is not checked; with none set the axis is unchecked.
struct ExpectedEncoder {
  std::string id_number;       // "1080790-02": the ID number as the identification prints it
  std::string serial_number;   // "S36845217"
  unsigned position_bits = 0;  // 0: any
  [[nodiscard]] bool any() const noexcept {
    return !id_number.empty() || !serial_number.empty() || position_bits != 0;
  }
};

// One additional-information channel (axes[].info, x20ds1928/info_channels.hpp): its name (the
// HAL pin's and metric's label), what EnDatInfoCmd0N asks for and how EnDatInfo0N reads.
struct InfoChannelConfig {
  std::string name;
  InfoRequest request;
  bool is_signed = false;
};

struct AxisConfig {
  std::string name;  // shown in status; default "axis<N>"
  uint8_t node = 1;  // POWERLINK CN node id / CAN-I/O node number / sim node
  uint8_t slot = 1;  // module position behind the bus controller (1-based)
  FunctionModel function_model = FunctionModel::Standard;
  ModuleSettings module;
  uint32_t command_timeout_ms = 2000;        // EnDat command over Flatstream
  uint32_t flatstream_timeout_cycles = 200;  // per-sequence timeout
  // POWERLINK only: byte offset of this module's block in its CN's PRes / PReq payload
  // (0..1489); unset = the default packed layout (docs/powerlink.md §Process image).
  std::optional<uint16_t> pres_offset;
  std::optional<uint16_t> preq_offset;
  ExpectedEncoder expected_encoder;
  // axes[].invalidate_on: per error bit (x20ds1928/error_bits.hpp), `true` makes a set bit
  // invalidate the position (hold it, for an analogue error), `false` only flags it; bits not
  // named keep their class' effect.
  ErrorMasks invalidate_on{};
  // axes[].info: channel N-1 is EnDatInfoCmd0N/EnDatInfo0N (module.info_cmd carries the
  // registers' values); at most kInfoChannels.
  std::vector<InfoChannelConfig> info;
  ErrorMasks flag_only_on{};
  [[nodiscard]] ErrorPolicy error_policy() const noexcept {
    return ds1928::error_policy(invalidate_on, flag_only_on);
  }
};

}  // namespace ds1928
