#include "canio/object_codec.hpp"

#include <algorithm>

#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::canio {
namespace {

// Offsets inside each 8-byte object from the object dictionary's offsets over the 16 input bytes.
constexpr std::size_t kHw = fm254::kPositionHw;
constexpr std::size_t kLw = fm254::kPositionLw;
constexpr std::size_t kSeq = fm254::kInputSequence - kObjectBytes;
constexpr std::size_t kRx = fm254::kRxBytes - kObjectBytes;
constexpr std::size_t kErr = fm254::kErrorInfo - kObjectBytes;
constexpr std::size_t kCycle = fm254::kPosCycle - kObjectBytes;
static_assert(kLw + 4 <= kObjectBytes && kCycle < kObjectBytes && kRx + fm254::kMaxMtu <= kErr);

void store32(uint8_t* p, uint32_t v, ByteOrder order) noexcept {
  for (std::size_t i = 0; i < 4; ++i) {
    const std::size_t shift = order == ByteOrder::Little ? 8 * i : 8 * (3 - i);
    p[i] = static_cast<uint8_t>(v >> shift);
  }
}

uint32_t load32(const uint8_t* p, ByteOrder order) noexcept {
  uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const std::size_t shift = order == ByteOrder::Little ? 8 * i : 8 * (3 - i);
    v |= static_cast<uint32_t>(p[i]) << shift;
  }
  return v;
}

}  // namespace

void pack_position_object(const ModuleInputs& in, ByteOrder order, CanObject& out) noexcept {
  store32(out.data() + kHw, in.position_hw, order);
  store32(out.data() + kLw, in.position_lw, order);
}

void pack_status_object(const ModuleInputs& in, CanObject& out) noexcept {
  out[kSeq] = in.input_sequence;
  std::copy_n(in.rx_bytes.begin(), fm254::kMaxMtu, out.begin() + kRx);
  out[kErr] = in.error_info;
  out[kCycle] = static_cast<uint8_t>(in.pos_cycle);
}

bool unpack_position_object(std::span<const uint8_t> bytes, ByteOrder order,
                            ModuleInputs& in) noexcept {
  if (bytes.size() != kObjectBytes) return false;
  in.position_hw = load32(bytes.data() + kHw, order);
  in.position_lw = load32(bytes.data() + kLw, order);
  return true;
}

bool unpack_status_object(std::span<const uint8_t> bytes, ModuleInputs& in) noexcept {
  if (bytes.size() != kObjectBytes) return false;
  in.input_sequence = bytes[kSeq];
  std::fill(in.rx_bytes.begin(), in.rx_bytes.end(), uint8_t{0});
  std::copy_n(bytes.begin() + kRx, fm254::kMaxMtu, in.rx_bytes.begin());
  in.error_info = bytes[kErr];
  in.pos_cycle = static_cast<int8_t>(bytes[kCycle]);
  // Function model 254 carries neither PosTime nor SDCLifeCount.
  in.pos_time_us = 0;
  in.sdc_life_count = 0;
  return true;
}

void pack_output_object(const ModuleOutputs& out, CanObject& bytes) noexcept {
  bytes.fill(0);
  bytes[fm254::kOutputSequence] = out.output_sequence;
  std::copy_n(out.tx_bytes.begin(), fm254::kMaxMtu, bytes.begin() + fm254::kTxBytes);
  bytes[fm254::kAckErrorInfo] = out.ack_error_info;
}

bool unpack_output_object(std::span<const uint8_t> bytes, ModuleOutputs& out) noexcept {
  if (bytes.size() < fm254::kAckErrorInfo + 1 || bytes.size() > kObjectBytes) return false;
  out.output_sequence = bytes[fm254::kOutputSequence];
  std::fill(out.tx_bytes.begin(), out.tx_bytes.end(), uint8_t{0});
  std::copy_n(bytes.begin() + fm254::kTxBytes, fm254::kMaxMtu, out.tx_bytes.begin());
  out.ack_error_info = bytes[fm254::kAckErrorInfo];
  return true;
}

}  // namespace ds1928::canio
