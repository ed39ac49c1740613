#include "sim/endat_bridge.hpp"

#include <algorithm>

#include "endat/wire.hpp"
#include "x20ds1928/module_image.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::sim {

using endat::Command;
using endat::CommandSet;
using endat::Errc;
using endat::FailureReason;
using endat::wire::BitFrame;
using endat::wire::Mode;

namespace {

constexpr uint8_t kStatusMrs = 0xB9;

bool crc_like(std::error_code ec) noexcept {
  return ec == Errc::crc_mismatch || ec == Errc::f2_not_inverted || ec == Errc::frame_length;
}

FailureReason reason_of(std::error_code ec) noexcept {
  if (ec == Errc::no_response) return FailureReason::NoResponse;
  if (ec == Errc::module_wire_echo_mismatch) return FailureReason::WireEchoMismatch;
  return FailureReason::CrcError;
}

}  // namespace

EnDatBridge::EnDatBridge(EnDatEncoder encoder, BridgeConfig config)
    : encoder_(std::move(encoder)), config_(config) {}

CommandSet EnDatBridge::command_set() const noexcept {
  return identification_ ? identification_->command_set : CommandSet::EnDat21;
}

// Clock: the module's fast 6 MHz clock for EnDat 2.2 encoders, 2 MHz for 2.1; plus recovery time.
int64_t EnDatBridge::wire_ns(std::size_t bits) const noexcept {
  const bool fast = command_set() == CommandSet::EnDat22;
  const int64_t per_bit_ns = fast ? 167 : 500;
  const int64_t recovery_ns = fast ? 2'500 : 10'000;
  return static_cast<int64_t>(bits + 4) * per_bit_ns + recovery_ns;
}

void EnDatBridge::note_failure(std::error_code ec) noexcept {
  if (crc_like(ec)) latched_ |= error_info::kEnDatComError;
}

// An acknowledge only clears what is gone: a bit whose condition persists stays latched and
// needs another acknowledge once the cause is removed.
void EnDatBridge::acknowledge_error_info(uint8_t bits) noexcept {
  latched_ &= static_cast<uint8_t>(~(bits & ~present_));
}

void EnDatBridge::update_f1(bool f1, int64_t now_ns) noexcept {
  if (f1) {
    present_ |= error_info::kEnDatPosError;
    latched_ |= error_info::kEnDatPosError;
  } else {
    present_ &= static_cast<uint8_t>(~error_info::kEnDatPosError);
  }
  if (f1 != last_f1_ && !status_due_) {
    status_due_ = true;
    status_due_ns_ = now_ns;
  }
  last_f1_ = f1;
}

Result<endat::wire::PositionReply> EnDatBridge::decode_position(const BitFrame& f,
                                                                CommandSet set) const {
  endat::wire::PositionFormat fmt{set, position_bits_, false, false};
  if (set == CommandSet::EnDat22 && f.size() > fmt.frame_bits()) {
    // Additional information present: how many follows from the length; which is in each
    // status byte. Knowing it from the frame keeps positions flowing even if a stop selection
    // was lost.
    const std::size_t extra = f.size() - fmt.frame_bits();
    if (extra == endat::wire::kAdditionalInfoBits) fmt.ai1 = true;
    if (extra == 2 * endat::wire::kAdditionalInfoBits) fmt.ai1 = fmt.ai2 = true;
  }
  return endat::wire::decode_position_reply(f, fmt);
}

// One wire transaction with the module's retries: `decode` turns the encoder's reply frame into a
// value or an error (no response, CRC), `accept` checks the value (echo) and stores it; the
// simulated time advances by what each attempt costs on the wire and in the encoder.
template <class Decode, class Accept>
std::error_code EnDatBridge::transact_retrying(int64_t& t, const BitFrame& frame, Decode decode,
                                               Accept accept) {
  std::error_code last;
  for (unsigned attempt = 0; attempt <= config_.max_retries; ++attempt) {
    if (attempt > 0) ++stats_.retries;
    ++stats_.transactions;
    const auto resp = encoder_.transact(frame, t);
    const auto reply = decode(resp.reply);
    if (!reply && reply.error() == Errc::no_response) {
      last = reply.error();
      ++stats_.no_responses;
      t += wire_ns(frame.size()) + config_.no_response_timeout_ns;
      continue;
    }
    t += wire_ns(frame.size() + resp.reply.size()) + resp.processing_ns;
    if (!reply) {
      last = reply.error();
      ++stats_.crc_errors;
      continue;
    }
    last = accept(*reply);
    if (!last) return {};
  }
  note_failure(last);
  return last;
}

std::error_code EnDatBridge::param_tx(int64_t& t, Mode mode, uint8_t address, uint16_t parameter,
                                      bool echo_value, uint16_t* value_out) {
  return transact_retrying(
      t, endat::wire::encode_master_frame({mode, address, parameter}),
      [](const BitFrame& f) { return endat::wire::decode_parameter_reply(f); },
      [&](const auto& reply) -> std::error_code {
        if (reply.address != address || (echo_value && reply.value != parameter))
          return Errc::module_wire_echo_mismatch;
        if (value_out != nullptr) *value_out = reply.value;
        return {};
      });
}

std::error_code EnDatBridge::position_tx(int64_t& t, Mode mode, uint8_t address, uint16_t parameter,
                                         endat::wire::PositionReply* out) {
  return transact_retrying(
      t, endat::wire::encode_master_frame({mode, address, parameter}),
      [this](const BitFrame& f) { return decode_position(f, CommandSet::EnDat22); },
      [&](const endat::wire::PositionReply& reply) -> std::error_code {
        if (out != nullptr) *out = reply;
        return {};
      });
}

std::error_code EnDatBridge::read_area(int64_t& t, uint8_t mrs, unsigned first,
                                       std::span<uint16_t> out) {
  if (auto ec = param_tx(t, Mode::SelectMemoryArea, mrs, 0, true, nullptr)) return ec;
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (auto ec =
            param_tx(t, Mode::SendParameter, static_cast<uint8_t>(first + i), 0, false, &out[i])) {
      return ec;
    }
  }
  return {};
}

std::error_code EnDatBridge::run_rescan(int64_t& t) {
  IdentRegisters fresh;
  std::error_code ec;
  for (unsigned page = 0; page < 3 && !ec; ++page) {
    ec = read_area(t, static_cast<uint8_t>(0xA1 + 2 * page), 0,
                   std::span<uint16_t>(fresh.manufacturer).subspan(page * 16, 16));
  }
  if (!ec) ec = read_area(t, 0xA7, 0, fresh.operating_param);
  if (!ec) ec = read_area(t, kStatusMrs, 0, fresh.operating_status);
  Result<endat::Identification> id = Errc::invalid_identification;
  if (!ec) {
    id = endat::decode_identification(fresh.manufacturer);
    if (!id) ec = id.error();
  }
  if (!ec && id->command_set == CommandSet::EnDat22) {
    ec = read_area(t, 0xBD, 1, std::span<uint16_t>(fresh.manufacturer_endat22).subspan(1));
  }
  if (ec) {
    ident_.valid = false;
    present_ |= error_info::kEnDatParSetError;
    latched_ |= error_info::kEnDatParSetError;
    return ec;
  }
  fresh.valid = true;
  ident_ = fresh;
  identification_ = *id;
  position_bits_ = id->position_bits;
  present_ &= static_cast<uint8_t>(~error_info::kEnDatParSetError);
  last_status_ns_ = t;
  return {};
}

std::error_code EnDatBridge::run_status_refresh(int64_t& t) {
  std::array<uint16_t, 2> words{};
  const auto ec = read_area(t, kStatusMrs, 0, words);
  if (!ec) {
    ident_.operating_status[0] = words[0];
    ident_.operating_status[1] = words[1];
  }
  last_status_ns_ = t;
  status_due_ = false;
  return ec;
}

std::error_code EnDatBridge::run_acknowledge(int64_t& t) {
  std::error_code ec;
  if (command_set() == CommandSet::EnDat22) {
    ec = position_tx(t, Mode::PositionAddInfoErrorReset, 0, 0, nullptr);
  } else {
    ec = param_tx(t, Mode::SelectMemoryArea, kStatusMrs, 0, true, nullptr);
    if (!ec) ec = param_tx(t, Mode::ReceiveParameter, 0, 0, true, nullptr);
    if (!ec) ec = param_tx(t, Mode::ReceiveParameter, 1, 0, true, nullptr);
  }
  if (ec) return ec;
  return run_status_refresh(t);
}

std::error_code EnDatBridge::run_info(const endat::Request& r, int64_t& t,
                                      std::array<uint16_t, 4>& words) {
  const uint8_t code = r.mrs;
  const unsigned wanted = endat::info_word_count(r.command);
  if (auto ec = position_tx(t, Mode::PositionAddInfoSelectMemory, code, 0, nullptr)) return ec;
  const BitFrame frame = endat::wire::encode_master_frame({Mode::PositionAddInfo, 0, 0});
  unsigned got = 0;
  bool saw_crc = false;
  for (unsigned f = 0; f < config_.max_info_frames && got < wanted; ++f) {
    t += config_.frame_interval_ns;
    ++stats_.transactions;
    const auto resp = encoder_.transact(frame, t);
    const auto reply = decode_position(resp.reply, CommandSet::EnDat22);
    if (!reply) {
      if (reply.error() == Errc::no_response) {
        ++stats_.no_responses;
      } else {
        ++stats_.crc_errors;
        saw_crc = true;
      }
      continue;
    }
    update_f1(reply->f1, t);
    for (const auto& ai : {reply->ai1, reply->ai2}) {
      if (ai && ai->which() == (code & 0x1F) && !ai->busy()) {
        words[got++] = ai->data;
        break;
      }
    }
  }
  // Stop the selection so that cyclic position frames go back to their plain length.
  (void)position_tx(t, Mode::PositionAddInfoSelectMemory, code < 0x50 ? 0x4F : 0x5F, 0, nullptr);
  if (got < wanted) {
    const std::error_code ec =
        saw_crc ? make_error_code(Errc::crc_mismatch) : make_error_code(Errc::no_response);
    note_failure(ec);
    return ec;
  }
  return {};
}

endat::ReplyMessage EnDatBridge::run_message(const Pending& p, int64_t& t) {
  ++stats_.messages;
  const auto bytes = p.bytes.span();
  const uint8_t first = bytes.empty() ? 0 : bytes[0];
  const auto request =
      p.too_long ? Result<endat::Request>(Errc::oversized_request) : endat::decode_request(bytes);
  if (!request) {
    ++stats_.failed_messages;
    return endat::encode_failure_reply(first, FailureReason::MalformedRequest);
  }
  const endat::Request& r = *request;
  if (endat::requires_endat22(r.command) && command_set() != CommandSet::EnDat22) {
    ++stats_.failed_messages;
    return endat::encode_failure_reply(first, FailureReason::NotSupported);
  }
  std::array<uint16_t, 4> words{};
  std::error_code ec;
  switch (r.command) {
    case Command::Reset:
      ec = param_tx(t, Mode::ReceiveReset, 0, 0, true, nullptr);
      if (!ec) {
        status_due_ = true;
        status_due_ns_ = t;
      }
      break;
    case Command::AcknowledgeErrors:
      ec = run_acknowledge(t);
      break;
    case Command::ReadParameter:
    case Command::ReadBlockParameter:
      ec = param_tx(t, Mode::SelectMemoryArea, r.mrs, r.block, true, nullptr);
      if (!ec) ec = param_tx(t, Mode::SendParameter, r.parameter, 0, false, &words[0]);
      break;
    case Command::WriteParameter:
    case Command::WriteBlockParameter:
      ec = param_tx(t, Mode::SelectMemoryArea, r.mrs, r.block, true, nullptr);
      if (!ec) ec = param_tx(t, Mode::ReceiveParameter, r.parameter, r.value, true, nullptr);
      break;
    case Command::ReadInfoWord1:
    case Command::ReadInfoWord2:
    case Command::ReadInfoWord3:
    case Command::ReadInfoWord4:
      ec = run_info(r, t, words);
      break;
  }
  if (ec) {
    ++stats_.failed_messages;
    return endat::encode_failure_reply(first, reason_of(ec));
  }
  return endat::encode_reply(r, words);
}

void EnDatBridge::service(int64_t now_ns) {
  if (in_flight_ && reset_in_flight_ && now_ns >= in_flight_->ready_ns) reset_in_flight_ = false;
  for (;;) {
    const int64_t free = channel_free_ns_;
    if (free > now_ns) return;
    int64_t t = 0;
    if (pending_rescan_) {
      pending_rescan_ = false;
      t = std::max(free, rescan_request_ns_);
      (void)run_rescan(t);
      rescan_done_ns_ = t;
    } else if (pending_ack_) {
      pending_ack_ = false;
      t = std::max(free, ack_request_ns_);
      (void)run_acknowledge(t);
      ack_done_ns_ = t;
    } else if (pending_) {
      t = std::max(free, pending_->submitted_ns);
      const bool is_reset = !pending_->bytes.span().empty() && pending_->bytes.span()[0] == 0x00;
      auto reply = run_message(*pending_, t);
      pending_.reset();
      in_flight_ = BridgeReply{reply, t};
      reset_in_flight_ = is_reset && t > now_ns;
    } else if (status_due_ || (config_.status_refresh_ns > 0 && identification_ &&
                               last_status_ns_ + config_.status_refresh_ns <= now_ns)) {
      t = std::max(free,
                   status_due_ ? status_due_ns_ : last_status_ns_ + config_.status_refresh_ns);
      (void)run_status_refresh(t);
    } else {
      return;
    }
    channel_free_ns_ = t;
  }
}

std::error_code EnDatBridge::power_up(int64_t now_ns) {
  int64_t t = now_ns;
  const auto ec = run_rescan(t);
  channel_free_ns_ = t;
  return ec;
}

void EnDatBridge::power_up_unread() noexcept {
  ident_ = IdentRegisters{};
  identification_.reset();
  position_bits_ = 0;
}

bool EnDatBridge::submit(std::span<const uint8_t> message, int64_t now_ns) {
  if (pending_ || in_flight_) return false;
  Pending p;
  for (uint8_t b : message) p.bytes.push(b);
  p.too_long = message.size() > p.bytes.bytes.size();
  p.submitted_ns = now_ns;
  pending_ = p;
  service(now_ns);
  return true;
}

std::optional<BridgeReply> EnDatBridge::poll(int64_t now_ns) {
  service(now_ns);
  if (!in_flight_ || in_flight_->ready_ns > now_ns) return std::nullopt;
  auto reply = *in_flight_;
  in_flight_.reset();
  reset_in_flight_ = false;
  service(now_ns);
  return reply;
}

bool EnDatBridge::idle() const noexcept {
  return !pending_ && !in_flight_;
}

void EnDatBridge::endat_ack(uint8_t bits, int64_t now_ns) {
  if ((bits & 0x01) != 0 && !pending_ack_) {
    pending_ack_ = true;
    ack_request_ns_ = now_ns;
  }
  if ((bits & 0x02) != 0 && !pending_rescan_) {
    pending_rescan_ = true;
    rescan_request_ns_ = now_ns;
  }
  service(now_ns);
}

PositionReading EnDatBridge::read_position(int64_t now_ns) {
  service(now_ns);  // jobs due by now have happened on the wire before this frame
  PositionReading out;
  out.steps = last_position_;
  if (position_bits_ == 0) {
    out.error = Errc::invalid_identification;
    return out;
  }
  const bool v22 = command_set() == CommandSet::EnDat22;
  const BitFrame frame =
      endat::wire::encode_master_frame({v22 ? Mode::PositionAddInfo : Mode::SendPosition, 0, 0});
  ++stats_.transactions;
  const auto resp = encoder_.transact(frame, now_ns);
  const auto reply = decode_position(resp.reply, command_set());
  if (!reply) {
    out.error = reply.error();
    // An encoder that is busy resetting on the module's own command is not a fault.
    const bool resetting = reset_in_flight_ && out.error == Errc::no_response;
    if (out.error == Errc::no_response) {
      ++stats_.no_responses;
    } else {
      ++stats_.crc_errors;
    }
    if (!resetting) {
      present_ |= error_info::kEnDatComError;
      latched_ |= error_info::kEnDatComError;
    }
    return out;
  }
  present_ &= static_cast<uint8_t>(~error_info::kEnDatComError);
  last_position_ = reply->position;
  out.steps = reply->position;
  out.fresh = true;
  out.encoder_error = reply->f1;
  update_f1(reply->f1, now_ns);
  return out;
}

std::optional<uint16_t> EnDatBridge::read_register(uint16_t reg) const noexcept {
  // The identification families of the object dictionary, each filled from its memory area.
  static_assert(od_entry("OperatingStatus_02..03").last() - reg::kOperatingStatus0 <
                std::tuple_size_v<decltype(ident_.operating_status)>);
  static_assert(od_entry("ParamManuf_04..47").last() - reg::kParamManuf0 <
                std::tuple_size_v<decltype(ident_.manufacturer)>);
  static_assert(od_entry("OperatingParam_00..15").last() - reg::kOperatingParam0 <
                std::tuple_size_v<decltype(ident_.operating_param)>);
  static_assert(od_entry("ParamManufEnDat22_01..63").last() - reg::kParamManufEnDat22_0 <
                std::tuple_size_v<decltype(ident_.manufacturer_endat22)>);
  const RegisterInfo* r = find_register(reg);
  if (!r) return std::nullopt;
  switch (r->number) {
    case reg::kEnDatError:
    case reg::kEnDatWarning:
    case reg::kOperatingStatus2:
      return ident_.operating_status[reg - reg::kOperatingStatus0];
    case reg::kParamManuf4:
      return ident_.manufacturer[reg - reg::kParamManuf0];
    case reg::kOperatingParam0:
      return ident_.operating_param[reg - reg::kOperatingParam0];
    case reg::kParamManufEnDat22_1:
      return ident_.manufacturer_endat22[reg - reg::kParamManufEnDat22_0];
    default:
      return std::nullopt;
  }
}

}  // namespace ds1928::sim
