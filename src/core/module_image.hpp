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

// Cyclic inputs (module → master), datasheet registers in brackets.
struct ModuleInputs {
  uint32_t position_hw = 0;    // PositionHW (4180)
  uint32_t position_lw = 0;    // PositionLW (4188)
  uint32_t pos_time_us = 0;    // PosTime 32-bit NetTime µs (4172); function model 0 only
  int8_t pos_cycle = 0;        // PosCycle (4163)
  int8_t sdc_life_count = 0;   // SDCLifeCount (683); function model 0 only
  uint8_t error_info = 0;      // ErrorInfo (261)
  uint8_t input_sequence = 0;  // InputSequence (4672)
  std::array<uint8_t, kMaxFlatstreamMtu> rx_bytes{};  // RxByte1.. (4673..)
};

// Cyclic outputs (master → module).
struct ModuleOutputs {
  uint8_t output_sequence = 0;                        // OutputSequence (4704)
  std::array<uint8_t, kMaxFlatstreamMtu> tx_bytes{};  // TxByte1.. (4705..)
  uint8_t ack_error_info = 0;                         // AckErrorInfo (325)
};

// Acyclic register numbers of the datasheet (function model 0 numbering; function model 254
// uses the same identifiers).
namespace reg {
inline constexpr uint16_t kSlframeGenId = 513;
inline constexpr uint16_t kSystemCyclePrescaler = 654;
inline constexpr uint16_t kErrorEnable = 389;
inline constexpr uint16_t kEnDatError = 4352;
inline constexpr uint16_t kEnDatWarning = 4353;
inline constexpr uint16_t kEnDatAck = 4099;
inline constexpr uint16_t kSinCosEnable = 1025;
inline constexpr uint16_t kSinCosRefSource = 1027;
inline constexpr uint16_t kSinCosVssMin = 1034;
inline constexpr uint16_t kSinCosVssMax = 1038;
inline constexpr uint16_t kSinCosQuitTime = 1044;
inline constexpr uint16_t kEnDatMode = 4097;
inline constexpr uint16_t kOperatingParam0 = 4400;      // + N, N = 0..15
inline constexpr uint16_t kOperatingStatus0 = 4352;     // + N, N = 0..3
inline constexpr uint16_t kParamManuf0 = 4352;          // + N, N = 4..47
inline constexpr uint16_t kParamManufEnDat22_0 = 4416;  // + N, N = 1..63
inline constexpr uint16_t kOutputMtu = 4609;
inline constexpr uint16_t kInputMtu = 4611;
inline constexpr uint16_t kFlatstreamMode = 4613;
inline constexpr uint16_t kForward = 4615;
inline constexpr uint16_t kForwardDelay = 4620;
}  // namespace reg

// EnDatMode (4097) bits.
namespace endat_mode {
inline constexpr uint8_t kEnable = 0x01;        // 1 = EnDat interface enabled
inline constexpr uint8_t kSigned = 0x02;        // 1 = position format signed
inline constexpr uint8_t kFastClockOff = 0x04;  // 1 = no 6 MHz clock
inline constexpr uint8_t kSinCosUnused = 0x08;  // 1 = sin/cos track not used
}  // namespace endat_mode

// ErrorInfo (261) / AckErrorInfo (325) bits.
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
