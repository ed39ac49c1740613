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

#include "flatstream/message.hpp"
#include "flatstream/protocol.hpp"
#include "flatstream/receiver.hpp"
#include "flatstream/sender.hpp"
#include "x20ds1928/module_image.hpp"

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

// One role's end of the channel: a sender for the direction it writes and a receiver for the
// direction it reads, both stepped once per bus cycle by the sequence register the peer sent.
// The roles differ only in which frame they send and which of their configuration's fields feed
// the sender and the receiver; `Role` names them (MasterRole, ModuleRole below).
template <class Role>
class Channel {
 public:
  using Config = typename Role::Config;
  using Received = typename Role::Received;
  using Sent = typename Role::Sent;

  explicit Channel(const Config& config) noexcept
      : config_(config), sender_(Role::sender(config)), receiver_(Role::receiver(config)) {}

  // One bus cycle: what the peer sent (its sequence register + MTU bytes) → what to send.
  [[nodiscard]] Sent step(const Received& received, uint64_t now_us) noexcept {
    const auto in = SequenceRegister::decode(Role::sequence(received));
    receiver_.step(in.counter, in.sync_bit, Role::bytes(received), now_us);
    sender_.step(in.ack, in.sync_ack, now_us);
    const SequenceRegister out{sender_.counter(), sender_.sync_bit(), receiver_.ack(),
                               receiver_.sync_ack()};
    return {out.encode(), sender_.mtu()};
  }

  // Queue a message for the peer (an EnDat command or reply). Errc::message_too_long /
  // Errc::queue_full.
  [[nodiscard]] std::error_code submit(std::span<const uint8_t> message, uint32_t tag) noexcept {
    return sender_.submit(message, tag);
  }
  // Complete messages from the peer, in order.
  [[nodiscard]] std::optional<Message> take_received() noexcept {
    std::optional<Message> out{std::in_place};
    if (!receiver_.take(*out)) out.reset();
    return out;
  }
  [[nodiscard]] bool take_received(Message& out) noexcept { return receiver_.take(out); }
  // One outcome per accepted submit, in submit order.
  [[nodiscard]] std::optional<SendOutcome> take_outcome() noexcept {
    SendOutcome o;
    if (!sender_.take_outcome(o)) return std::nullopt;
    return o;
  }

  [[nodiscard]] Counters counters() const noexcept {
    return {sender_.counters(), receiver_.counters()};
  }
  [[nodiscard]] ChannelState state() const noexcept { return {sender_.state(), receiver_.state()}; }
  [[nodiscard]] const Config& config() const noexcept { return config_; }

  // Both directions start again; queued and in-flight messages are reported failed.
  void reset() noexcept {
    sender_.reset();
    receiver_.reset();
  }
  // New MTUs, layout, Forward, ForwardDelay take effect here: both directions resynchronise.
  void configure(const Config& config) noexcept {
    config_ = config;
    sender_.configure(Role::sender(config));
    receiver_.configure(Role::receiver(config));
  }

 private:
  Config config_;
  SequenceSender sender_;
  SequenceReceiver receiver_;
};

// The daemon ("CPU"): sends OutputSequence + TxBytes, receives InputSequence + RxBytes.
struct MasterRole {
  using Config = MasterConfig;
  using Received = InputFrame;
  using Sent = OutputFrame;
  [[nodiscard]] static SenderConfig sender(const MasterConfig& c) noexcept {
    return {c.output_mtu, c.output_layout, c.output_forward, 0, c.timeout_cycles};
  }
  [[nodiscard]] static ReceiverConfig receiver(const MasterConfig& c) noexcept {
    return {c.input_mtu, 0};
  }
  [[nodiscard]] static uint8_t sequence(const InputFrame& f) noexcept { return f.input_sequence; }
  [[nodiscard]] static const MtuBytes& bytes(const InputFrame& f) noexcept { return f.rx; }
};

// The module (the simulator): sends InputSequence + RxBytes, receives OutputSequence + TxBytes.
struct ModuleRole {
  using Config = ModuleConfig;
  using Received = OutputFrame;
  using Sent = InputFrame;
  [[nodiscard]] static SenderConfig sender(const ModuleConfig& c) noexcept {
    return {c.input_mtu, static_cast<Layout>(c.flatstream_mode & 0x03), c.forward,
            c.forward_delay_us, c.timeout_cycles};
  }
  // ForwardDelay delays the module's acknowledgement in the output direction (datasheet
  // §11.9.5.2.2).
  [[nodiscard]] static ReceiverConfig receiver(const ModuleConfig& c) noexcept {
    return {c.output_mtu, c.forward_delay_us};
  }
  [[nodiscard]] static uint8_t sequence(const OutputFrame& f) noexcept { return f.output_sequence; }
  [[nodiscard]] static const MtuBytes& bytes(const OutputFrame& f) noexcept { return f.tx; }
};

using MasterChannel = Channel<MasterRole>;  // the daemon's side
using ModuleChannel = Channel<ModuleRole>;  // the module's side (used by the simulator)

}  // namespace ds1928::flatstream
