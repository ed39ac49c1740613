#include "flatstream/channel.hpp"

namespace ds1928::flatstream {
namespace {

bool mtu_ok(uint8_t mtu) noexcept {
  return mtu >= kMinMtu && mtu <= kMaxMtu;
}

SenderConfig master_sender(const MasterConfig& c) noexcept {
  return {c.output_mtu, c.output_layout, c.output_forward, 0, c.timeout_cycles};
}
ReceiverConfig master_receiver(const MasterConfig& c) noexcept {
  return {c.input_mtu, 0};
}
SenderConfig module_sender(const ModuleConfig& c) noexcept {
  return {c.input_mtu, static_cast<Layout>(c.flatstream_mode & 0x03), c.forward, c.forward_delay_us,
          c.timeout_cycles};
}
// ForwardDelay delays the module's acknowledgement in the output direction (datasheet §11.9.5.2.2).
ReceiverConfig module_receiver(const ModuleConfig& c) noexcept {
  return {c.output_mtu, c.forward_delay_us};
}

}  // namespace

std::error_code validate(const MasterConfig& c) noexcept {
  if (!mtu_ok(c.output_mtu) || !mtu_ok(c.input_mtu)) return Errc::invalid_mtu;
  if (static_cast<uint8_t>(c.output_layout) > 3) return Errc::invalid_layout;
  if (c.output_forward < 1 || c.output_forward > kMaxForward) return Errc::invalid_forward;
  if (c.timeout_cycles == 0) return Errc::invalid_timeout;
  return {};
}

std::error_code validate(const ModuleConfig& c) noexcept {
  if (!mtu_ok(c.output_mtu) || !mtu_ok(c.input_mtu)) return Errc::invalid_mtu;
  if (c.flatstream_mode > 3) return Errc::invalid_layout;
  if (c.forward < 1 || c.forward > kMaxForward) return Errc::invalid_forward;
  if (c.timeout_cycles == 0) return Errc::invalid_timeout;
  return {};
}

// ---- MasterChannel -----------------------------------------------------------------------

MasterChannel::MasterChannel(const MasterConfig& config) noexcept
    : config_(config), sender_(master_sender(config)), receiver_(master_receiver(config)) {}

OutputFrame MasterChannel::step(const InputFrame& received, uint64_t now_us) noexcept {
  const auto in = SequenceRegister::decode(received.input_sequence);
  receiver_.step(in.counter, in.sync_bit, received.rx, now_us);
  sender_.step(in.ack, in.sync_ack, now_us);
  const SequenceRegister out{sender_.counter(), sender_.sync_bit(), receiver_.ack(),
                             receiver_.sync_ack()};
  return {out.encode(), sender_.mtu()};
}

std::error_code MasterChannel::submit(std::span<const uint8_t> message, uint32_t tag) noexcept {
  return sender_.submit(message, tag);
}

std::optional<Message> MasterChannel::take_received() noexcept {
  std::optional<Message> out{std::in_place};
  if (!receiver_.take(*out)) out.reset();
  return out;
}

std::optional<SendOutcome> MasterChannel::take_outcome() noexcept {
  SendOutcome o;
  if (!sender_.take_outcome(o)) return std::nullopt;
  return o;
}

Counters MasterChannel::counters() const noexcept {
  return {sender_.counters(), receiver_.counters()};
}
ChannelState MasterChannel::state() const noexcept {
  return {sender_.state(), receiver_.state()};
}

void MasterChannel::reset() noexcept {
  sender_.reset();
  receiver_.reset();
}

void MasterChannel::configure(const MasterConfig& config) noexcept {
  config_ = config;
  sender_.configure(master_sender(config));
  receiver_.configure(master_receiver(config));
}

// ---- ModuleChannel -----------------------------------------------------------------------

ModuleChannel::ModuleChannel(const ModuleConfig& config) noexcept
    : config_(config), sender_(module_sender(config)), receiver_(module_receiver(config)) {}

InputFrame ModuleChannel::step(const OutputFrame& received, uint64_t now_us) noexcept {
  const auto in = SequenceRegister::decode(received.output_sequence);
  receiver_.step(in.counter, in.sync_bit, received.tx, now_us);
  sender_.step(in.ack, in.sync_ack, now_us);
  const SequenceRegister out{sender_.counter(), sender_.sync_bit(), receiver_.ack(),
                             receiver_.sync_ack()};
  return {out.encode(), sender_.mtu()};
}

std::error_code ModuleChannel::submit(std::span<const uint8_t> message, uint32_t tag) noexcept {
  return sender_.submit(message, tag);
}

std::optional<Message> ModuleChannel::take_received() noexcept {
  std::optional<Message> out{std::in_place};
  if (!receiver_.take(*out)) out.reset();
  return out;
}

std::optional<SendOutcome> ModuleChannel::take_outcome() noexcept {
  SendOutcome o;
  if (!sender_.take_outcome(o)) return std::nullopt;
  return o;
}

Counters ModuleChannel::counters() const noexcept {
  return {sender_.counters(), receiver_.counters()};
}
ChannelState ModuleChannel::state() const noexcept {
  return {sender_.state(), receiver_.state()};
}

void ModuleChannel::reset() noexcept {
  sender_.reset();
  receiver_.reset();
}

void ModuleChannel::configure(const ModuleConfig& config) noexcept {
  config_ = config;
  sender_.configure(module_sender(config));
  receiver_.configure(module_receiver(config));
}

}  // namespace ds1928::flatstream
