// Settings a master writes into one X20DS1928 at start (X20DS1928.md §3). Defaults are the
// datasheet's unless noted; the registers they land in and the order of the writes are in the
// object dictionary (x20ds1928/object_dictionary.hpp).
#pragma once

#include <array>
#include <cstdint>

#include "x20ds1928/module_image.hpp"

namespace ds1928 {

struct ModuleSettings {
  // EnDatMode bits. The datasheet's default is 0 (interface disabled); the daemon defaults to
  // enabled because a master that does not enable the encoder reads nothing.
  bool endat_enable = true;
  bool position_signed = false;
  bool fast_clock_off = false;
  bool sincos_unused = false;
  uint16_t prescaler = 2;          // CfO_SystemCyclePrescaler, EnDat cycle = module cycle × this
  uint8_t slframe_gen_id = 14;     // CfO_SlframeGenID: 9 fastest, 14 X2X-aligned (default)
  uint8_t error_enable = 0xFF;     // ErrorEnableID_1710
  uint16_t vss_min_mv = 800;       // SinCosVssMin 0..1500
  uint16_t vss_max_mv = 1200;      // SinCosVssMax 0..1500
  uint32_t quit_time_us = 100000;  // SinCosQuitTime 0..20 000 000
  uint8_t output_mtu = 7;          // OutputMTU (Tx bytes), ≤15 (model 0) / ≤5 (model 254)
  uint8_t input_mtu = 7;           // InputMTU (Rx bytes)
  uint8_t flatstream_mode = 0;     // bit 0 MultiSegmentMTU, bit 1 large segments
  uint8_t forward = 1;             // 1..7
  uint16_t forward_delay_us = 0;   // ForwardDelay
  // EnDatInfoCmd01..04 (x20ds1928/info_channels.hpp's layout); 0 = channel off, the datasheet's
  // default. From axes[].info.
  std::array<uint32_t, 4> info_cmd{};

  [[nodiscard]] uint8_t endat_mode() const noexcept {
    return static_cast<uint8_t>((endat_enable ? endat_mode::kEnable : 0) |
                                (position_signed ? endat_mode::kSigned : 0) |
                                (fast_clock_off ? endat_mode::kFastClockOff : 0) |
                                (sincos_unused ? endat_mode::kSinCosUnused : 0));
  }
};

}  // namespace ds1928
