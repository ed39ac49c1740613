// Flatstream channels, one per role, each driven once per bus cycle:
//   MasterChannel (the daemon, "CPU"): output sender + input receiver;
//     step(InputSequence + RxBytes received) → OutputSequence + TxBytes to send.
//   ModuleChannel (the simulated X20DS1928): output receiver + input sender;
//     step(OutputSequence + TxBytes received) → InputSequence + RxBytes to send.
// The frame types differ per direction, so two channels of the same role cannot be wired to each
// other: MasterChannel::step neither takes nor returns what another MasterChannel produces.
// Pure: no I/O, no clocks (time comes in as `now_us`), no threads, no allocation.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <system_error>

#include "core/module_image.hpp"
#include "flatstream/message.hpp"
#include "flatstream/protocol.hpp"
#include "flatstream/receiver.hpp"
#include "flatstream/sender.hpp"

namespace ds1928::flatstream {

// CPU → module: OutputSequence + TxBytes.
struct OutputFrame {
  uint8_t output_sequence = 0;
  MtuBytes tx{};
};
// Module → CPU: InputSequence + RxBytes.
struct InputFrame {
  uint8_t input_sequence = 0;
  MtuBytes rx{};
};

[[nodiscard]] inline InputFrame input_frame(const ModuleInputs& in) noexcept {
  return {in.input_sequence, in.rx_bytes};
}
[[nodiscard]] inline OutputFrame output_frame(const ModuleOutputs& out) noexcept {
  return {out.output_sequence, out.tx_bytes};
}
inline void apply(const OutputFrame& f, ModuleOutputs& out) noexcept {
  out.output_sequence = f.output_sequence;
  out.tx_bytes = f.tx;
}
inline void apply(const InputFrame& f, ModuleInputs& in) noexcept {
  in.input_sequence = f.input_sequence;
  in.rx_bytes = f.rx;
}

struct MasterConfig {
  uint8_t output_mtu = 7;  // OutputMTU (TxBytes), 2..27
  uint8_t input_mtu = 7;   // InputMTU (RxBytes), 2..27
  // Layout of the output direction; the module accepts every layout there (datasheet §11.9.4.8).
  Layout output_layout = Layout::LargeMultiSegment;
  // Unacknowledged output sequences, 1..7. Keep 1 when the module's ForwardDelay is longer than
  // the bus cycle (it takes sequences more slowly than one per cycle).
  uint8_t output_forward = 1;
  uint32_t timeout_cycles = 200;  // per-sequence timeout
};

struct ModuleConfig {
  uint8_t output_mtu = 7;         // OutputMTU
  uint8_t input_mtu = 7;          // InputMTU
  uint8_t flatstream_mode = 0;    // FlatstreamMode: bit 0 MultiSegmentMTU, bit 1 large
  uint8_t forward = 1;            // Forward, 1..7
  uint16_t forward_delay_us = 0;  // ForwardDelay
  uint32_t timeout_cycles = 200;  // per-sequence timeout of the input sender
};

// Precise reason a configuration is unusable; channels clamp out-of-range values instead.
[[nodiscard]] std::error_code validate(const MasterConfig& config) noexcept;
[[nodiscard]] std::error_code validate(const ModuleConfig& config) noexcept;

struct Counters {
  SenderCounters sent;        // this role's sending direction
  ReceiverCounters received;  // this role's receiving direction
};

struct ChannelState {
  SenderState sending;
  ReceiverState receiving;
};

// The daemon's side.
class MasterChannel {
 public:
  explicit MasterChannel(const MasterConfig& config) noexcept;

  // One bus cycle: what the module sent (InputSequence + RxBytes) → what to send.
  [[nodiscard]] OutputFrame step(const InputFrame& received, uint64_t now_us) noexcept;

  // Queue an output message (EnDat command). Errc::message_too_long / Errc::queue_full.
  [[nodiscard]] std::error_code submit(std::span<const uint8_t> message, uint32_t tag) noexcept;
  // Complete input messages, in order.
  [[nodiscard]] std::optional<Message> take_received() noexcept;
  [[nodiscard]] bool take_received(Message& out) noexcept { return receiver_.take(out); }
  // One outcome per accepted submit, in submit order.
  [[nodiscard]] std::optional<SendOutcome> take_outcome() noexcept;

  [[nodiscard]] Counters counters() const noexcept;
  [[nodiscard]] ChannelState state() const noexcept;
  [[nodiscard]] const MasterConfig& config() const noexcept { return config_; }
  // Both directions start again; queued and in-flight output messages are reported failed.
  void reset() noexcept;
  void configure(const MasterConfig& config) noexcept;

 private:
  MasterConfig config_;
  SequenceSender sender_;
  SequenceReceiver receiver_;
};

// The module's side (used by the simulator).
class ModuleChannel {
 public:
  explicit ModuleChannel(const ModuleConfig& config) noexcept;

  // One bus cycle: what the CPU sent (OutputSequence + TxBytes) → what to send.
  [[nodiscard]] InputFrame step(const OutputFrame& received, uint64_t now_us) noexcept;

  // Queue an input message (EnDat reply).
  [[nodiscard]] std::error_code submit(std::span<const uint8_t> message, uint32_t tag) noexcept;
  // Complete output messages (EnDat commands), in order.
  [[nodiscard]] std::optional<Message> take_received() noexcept;
  [[nodiscard]] bool take_received(Message& out) noexcept { return receiver_.take(out); }
  [[nodiscard]] std::optional<SendOutcome> take_outcome() noexcept;

  [[nodiscard]] Counters counters() const noexcept;
  [[nodiscard]] ChannelState state() const noexcept;
  [[nodiscard]] const ModuleConfig& config() const noexcept { return config_; }
  void reset() noexcept;
  // Register writes (MTUs, FlatstreamMode, Forward, ForwardDelay) take effect here: both
  // directions resynchronise.
  void configure(const ModuleConfig& config) noexcept;

 private:
  ModuleConfig config_;
  SequenceSender sender_;
  SequenceReceiver receiver_;
};

}  // namespace ds1928::flatstream
