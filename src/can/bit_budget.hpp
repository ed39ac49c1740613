// Bits on the wire of classic CAN frames and the time a CAN-I/O cycle occupies the bus.
//
// A CAN 2.0A data frame with n data bytes is 47 + 8n bits including the 3-bit intermission:
// SOF 1, identifier 11, RTR 1, IDE 1, r0 1, DLC 4, data 8n, CRC 15 (these 34 + 8n bits are
// subject to bit stuffing), CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7, IFS 3 (13 bits,
// never stuffed). After five equal bits the transmitter inserts a complementary stuff bit; in the
// worst case the first stuff bit comes after 5 bits and every further one after 4 (the stuff bit
// starts the next run), so L stuffable bits carry at most 1 + floor((L - 5) / 4) = floor((L - 1) /
// 4) stuff bits (Davis, Burns, Bril, Lukkien, "Controller Area Network (CAN) schedulability
// analysis: refuted, revisited and revised", Real-Time Systems 35, 2007, eq. 2; CAN 2.0 part A
// §3.1.1 frame layout, §5 bit stuffing). 8 data bytes: 111 bits nominal, 135 worst case.
// A 2.0B frame (29-bit id) adds SRR, IDE and 18 identifier bits: 67 + 8n, 54 + 8n stuffable.
#pragma once

#include <cstdint>

#include "can/can_frame.hpp"

namespace ds1928::canio {

struct FrameBits {
  uint32_t nominal = 0;     // without stuff bits
  uint32_t worst_case = 0;  // with the most stuff bits the frame can carry
};

// dlc above 8 is taken as 8 (a classic frame never carries more). Remote frames carry no data
// bits: pass data_bytes 0.
[[nodiscard]] constexpr FrameBits frame_bits(uint32_t data_bytes,
                                             bool extended_id = false) noexcept {
  const uint32_t n = data_bytes > 8 ? 8 : data_bytes;
  const uint32_t stuffable = (extended_id ? 54u : 34u) + 8u * n;
  const uint32_t fixed = 13u;  // CRC delimiter, ACK slot + delimiter, EOF, intermission
  return {stuffable + fixed, stuffable + fixed + (stuffable - 1u) / 4u};
}

// The bits one particular frame puts on the wire, from its real bit sequence: SOF, identifier
// (2.0A: 11 bits, RTR, IDE, r0; 2.0B: 11 base bits, SRR, IDE, 18 extension bits, RTR, r1, r0),
// DLC, the data bytes (none in a remote frame), the CRC-15 over all of these (polynomial 0x4599,
// CAN 2.0 part A §3.1.1.6), and the stuff bits a transmitter inserts into them (after five equal
// bits a complementary bit, which counts towards the next run), then the 13 bits never stuffed
// (CRC delimiter, ACK slot, ACK delimiter, EOF 7, intermission 3). Pure.
struct FrameWire {
  uint32_t stuffable = 0;  // SOF .. last CRC bit, before stuffing
  uint32_t stuff = 0;      // stuff bits inserted into them
  uint32_t total = 0;      // stuffable + stuff + 13: the bus time of the frame in bits
  uint16_t crc = 0;        // the frame's CRC-15
};
inline constexpr uint32_t kUnstuffedTailBits = 13;  // CRC delim, ACK, ACK delim, EOF 7, IFS 3
inline constexpr uint32_t kIntermissionBits = 3;

[[nodiscard]] FrameWire frame_wire(const CanFrame& frame) noexcept;
// frame_wire(frame).total.
[[nodiscard]] uint32_t frame_wire_bits(const CanFrame& frame) noexcept;
// Bits at a bit rate in ns, rounded up (bitrate 0: 0).
[[nodiscard]] int64_t bits_to_ns(uint64_t bits, uint32_t bitrate) noexcept;

// The frames of one CAN-I/O cycle: per module two 8-byte input objects and one output object
// (X20DS1928 function model 254, spec §2.2), and optionally one SYNC frame for the whole bus.
struct CycleLoad {
  uint32_t modules = 1;
  uint32_t bitrate = 500'000;  // bit/s
  bool sync = false;
  uint32_t sync_bytes = 0;  // CANopen SYNC carries no data (or 1 byte with a counter)
  uint32_t input_frames_per_module = 2;
  uint32_t input_bytes = 8;
  uint32_t output_frames_per_module = 1;
  uint32_t output_bytes = 8;
  bool extended_ids = false;
};

struct CycleBudget {
  uint32_t frames = 0;
  uint64_t bits_nominal = 0;
  uint64_t bits_worst_case = 0;
  int64_t time_nominal_ns = 0;     // bits_nominal at the bit rate (rounded up)
  int64_t time_worst_case_ns = 0;  // bits_worst_case at the bit rate (rounded up): the shortest
                                   // cycle the bus allows
};

// bitrate 0 gives times of 0 (the caller refuses such a configuration before).
[[nodiscard]] CycleBudget cycle_budget(const CycleLoad& load) noexcept;

// Does the cycle fit the period? Numbers only; the caller words the message.
struct CycleFit {
  bool fits = false;             // worst case fits the period
  bool fits_nominal = false;     // nominal fits (worst case may not)
  int64_t margin_ns = 0;         // period - worst-case time (negative: short by that much)
  double load_worst_case = 0.0;  // worst-case bus time / period (1.0 = saturated)
  double load_nominal = 0.0;
  CycleBudget budget;
};

[[nodiscard]] CycleFit check_cycle(const CycleLoad& load, int64_t period_ns) noexcept;

}  // namespace ds1928::canio
