// Register image of one X20DS1928 as the cyclic bus carries it, independent of the bus.
// Bus drivers map their wire bytes (POWERLINK PRes/PReq offsets, CAN objects) to and from
// these structs; everything above the bus sees only this view.
#pragma once

#include <array>
#include <cstdint>

namespace ds1928 {

// Flatstream allows up to 27 bytes per direction; this module uses at most 15 (function model 0).
inline constexpr std::size_t kMaxFlatstreamMtu = 27;

enum class FunctionModel : uint8_t { Standard = 0, BusController = 254 };

// Cyclic inputs (module → master), named by their registers (x20ds1928/object_dictionary.hpp).
struct ModuleInputs {
  uint32_t position_hw = 0;    // PositionHW
  uint32_t position_lw = 0;    // PositionLW
  uint32_t pos_time_us = 0;    // PosTime 32-bit NetTime µs; function model 0 only
  int8_t pos_cycle = 0;        // PosCycle
  int8_t sdc_life_count = 0;   // SDCLifeCount; function model 0 only
  uint8_t error_info = 0;      // ErrorInfo
  uint8_t input_sequence = 0;  // InputSequence
  std::array<uint8_t, kMaxFlatstreamMtu> rx_bytes{};  // RxByte1..
  // The additional-information channels (§11.8.3): EnDatInfoOK bits 0..3 and EnDatInfo01..04.
  // Read acyclically on the buses the daemon drives (docs/registers.md §Additional information).
  uint8_t info_ok = 0;
  std::array<uint16_t, 4> info{};
};

// Cyclic outputs (master → module).
struct ModuleOutputs {
  uint8_t output_sequence = 0;                        // OutputSequence
  std::array<uint8_t, kMaxFlatstreamMtu> tx_bytes{};  // TxByte1..
  uint8_t ack_error_info = 0;                         // AckErrorInfo
};

// EnDatMode bits.
namespace endat_mode {
inline constexpr uint8_t kEnable = 0x01;        // 1 = EnDat interface enabled
inline constexpr uint8_t kSigned = 0x02;        // 1 = position format signed
inline constexpr uint8_t kFastClockOff = 0x04;  // 1 = no 6 MHz clock
inline constexpr uint8_t kSinCosUnused = 0x08;  // 1 = sin/cos track not used
}  // namespace endat_mode

// ErrorInfo / AckErrorInfo bits.
namespace error_info {
inline constexpr uint8_t kEncoderSupplyError = 0x01;
inline constexpr uint8_t kVssCheckError = 0x04;
inline constexpr uint8_t kPositionError = 0x08;
inline constexpr uint8_t kEnDatComError = 0x10;
inline constexpr uint8_t kEnDatPosError = 0x20;
inline constexpr uint8_t kEnDatParSetError = 0x40;
inline constexpr uint8_t kEnDatRefWarning = 0x80;
}  // namespace error_info

}  // namespace ds1928
