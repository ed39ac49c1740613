#include "endat/wire.hpp"

#include "endat/crc.hpp"

namespace ds1928::endat::wire {

bool BitFrame::read_msb_first(std::size_t& pos, unsigned count, uint64_t& out) const noexcept {
  if (count > 64 || pos + count > size_) return false;
  uint64_t v = 0;
  for (unsigned i = 0; i < count; ++i) v = (v << 1) | bits_[pos + i];
  pos += count;
  out = v;
  return true;
}

bool BitFrame::read_lsb_first(std::size_t& pos, unsigned count, uint64_t& out) const noexcept {
  if (count > 64 || pos + count > size_) return false;
  uint64_t v = 0;
  for (unsigned i = 0; i < count; ++i) v |= static_cast<uint64_t>(bits_[pos + i]) << i;
  pos += count;
  out = v;
  return true;
}

std::optional<Mode> mode_from_bits(uint8_t b) noexcept {
  switch (b) {
    case 0x07:
    case 0x0E:
    case 0x1C:
    case 0x23:
    case 0x2A:
    case 0x15:
    case 0x31:
    case 0x38:
    case 0x09:
    case 0x1B:
    case 0x24:
    case 0x2D:
    case 0x36:
    case 0x12:
      return static_cast<Mode>(b);
    default:
      return std::nullopt;
  }
}

bool is_endat22_mode(Mode m) noexcept {
  switch (m) {
    case Mode::PositionAddInfo:
    case Mode::PositionAddInfoSelectMemory:
    case Mode::PositionAddInfoReceiveParameter:
    case Mode::PositionAddInfoSendParameter:
    case Mode::PositionAddInfoErrorReset:
    case Mode::PositionAddInfoTestCommand:
    case Mode::CommunicationCommand:
      return true;
    default:
      return false;
  }
}

bool has_parameter_field(Mode m) noexcept {
  return m != Mode::SendPosition && m != Mode::PositionAddInfo && m != Mode::SendTestValues;
}

bool answers_with_position(Mode m) noexcept {
  switch (m) {
    case Mode::SendPosition:
    case Mode::PositionAddInfo:
    case Mode::PositionAddInfoSelectMemory:
    case Mode::PositionAddInfoReceiveParameter:
    case Mode::PositionAddInfoSendParameter:
    case Mode::PositionAddInfoErrorReset:
    case Mode::PositionAddInfoTestCommand:
      return true;
    default:
      return false;
  }
}

BitFrame encode_master_frame(const MasterFrame& f) noexcept {
  BitFrame b;
  b.push_msb_first(static_cast<uint8_t>(f.mode), 6);
  if (has_parameter_field(f.mode)) {
    b.push_msb_first(f.address, 8);
    b.push_msb_first(f.parameter, 16);
  }
  return b;
}

Result<MasterFrame> decode_master_frame(const BitFrame& bits) noexcept {
  std::size_t pos = 0;
  uint64_t v = 0;
  if (!bits.read_msb_first(pos, 6, v)) return Errc::frame_length;
  const auto mode = mode_from_bits(static_cast<uint8_t>(v));
  if (!mode) return Errc::invalid_mode;
  MasterFrame f;
  f.mode = *mode;
  if (has_parameter_field(f.mode)) {
    uint64_t a = 0, p = 0;
    if (!bits.read_msb_first(pos, 8, a) || !bits.read_msb_first(pos, 16, p)) {
      return Errc::frame_length;
    }
    f.address = static_cast<uint8_t>(a);
    f.parameter = static_cast<uint16_t>(p);
  }
  if (pos != bits.size()) return Errc::frame_length;
  return f;
}

BitFrame encode_parameter_reply(const ParameterReply& r) noexcept {
  BitFrame b;
  b.push_bit(true);  // start bit
  b.push_msb_first(r.address, 8);
  b.push_msb_first(r.value, 16);
  b.push_msb_first(crc5_parameter(r.address, r.value), 5);
  return b;
}

Result<ParameterReply> decode_parameter_reply(const BitFrame& bits) noexcept {
  if (bits.empty() || !bits.bit(0)) return Errc::no_response;
  if (bits.size() != kParameterReplyBits) return Errc::frame_length;
  std::size_t pos = 1;
  uint64_t a = 0, v = 0, crc = 0;
  (void)bits.read_msb_first(pos, 8, a);
  (void)bits.read_msb_first(pos, 16, v);
  (void)bits.read_msb_first(pos, 5, crc);
  ParameterReply r{static_cast<uint8_t>(a), static_cast<uint16_t>(v)};
  if (crc5_parameter(r.address, r.value) != crc) return Errc::crc_mismatch;
  return r;
}

std::size_t PositionFormat::frame_bits() const noexcept {
  const bool v22 = set == CommandSet::EnDat22;
  std::size_t n = 1 + 1 + (v22 ? 1 : 0) + position_bits + 5;
  if (v22 && ai1) n += kAdditionalInfoBits;
  if (v22 && ai2) n += kAdditionalInfoBits;
  return n;
}

namespace {

void push_additional_info(BitFrame& b, const AdditionalInfo& ai) noexcept {
  Crc5 crc;
  crc.push_msb_first(ai.status, 8);
  crc.push_msb_first(ai.data, 16);
  b.push_msb_first(ai.status, 8);
  b.push_msb_first(ai.data, 16);
  b.push_msb_first(crc.value(), 5);
}

Result<AdditionalInfo> read_additional_info(const BitFrame& b, std::size_t& pos) noexcept {
  uint64_t s = 0, d = 0, c = 0;
  if (!b.read_msb_first(pos, 8, s) || !b.read_msb_first(pos, 16, d) ||
      !b.read_msb_first(pos, 5, c)) {
    return Errc::frame_length;
  }
  Crc5 crc;
  crc.push_msb_first(s, 8);
  crc.push_msb_first(d, 16);
  if (crc.value() != c) return Errc::crc_mismatch;
  return AdditionalInfo{static_cast<uint8_t>(s), static_cast<uint16_t>(d)};
}

}  // namespace

BitFrame encode_position_reply(const PositionReply& r, CommandSet set,
                               unsigned position_bits) noexcept {
  const bool v22 = set == CommandSet::EnDat22;
  const uint64_t mask = position_bits >= 64 ? ~uint64_t{0} : ((uint64_t{1} << position_bits) - 1);
  Crc5 crc;
  BitFrame b;
  b.push_bit(true);  // start bit
  b.push_bit(r.f1);
  crc.push_bit(r.f1);
  if (v22) {
    b.push_bit(r.f2);
    crc.push_bit(r.f2);
  }
  b.push_lsb_first(r.position & mask, position_bits);
  crc.push_lsb_first(r.position & mask, position_bits);
  b.push_msb_first(crc.value(), 5);
  if (v22 && r.ai1) push_additional_info(b, *r.ai1);
  if (v22 && r.ai2) push_additional_info(b, *r.ai2);
  return b;
}

Result<PositionReply> decode_position_reply(const BitFrame& bits,
                                            const PositionFormat& format) noexcept {
  if (bits.empty() || !bits.bit(0)) return Errc::no_response;
  if (format.position_bits == 0 || format.position_bits > kMaxPositionBits ||
      bits.size() != format.frame_bits()) {
    return Errc::frame_length;
  }
  const bool v22 = format.set == CommandSet::EnDat22;
  std::size_t pos = 1;
  PositionReply r;
  Crc5 crc;
  r.f1 = bits.bit(pos++);
  crc.push_bit(r.f1);
  if (v22) {
    r.f2 = bits.bit(pos++);
    crc.push_bit(r.f2);
  }
  uint64_t p = 0, c = 0;
  (void)bits.read_lsb_first(pos, format.position_bits, p);
  (void)bits.read_msb_first(pos, 5, c);
  crc.push_lsb_first(p, format.position_bits);
  if (crc.value() != c) return Errc::crc_mismatch;
  if (v22 && r.f1 == r.f2) return Errc::f2_not_inverted;
  r.position = p;
  if (v22 && format.ai1) {
    auto ai = read_additional_info(bits, pos);
    if (!ai) return ai.error();
    r.ai1 = *ai;
  }
  if (v22 && format.ai2) {
    auto ai = read_additional_info(bits, pos);
    if (!ai) return ai.error();
    r.ai2 = *ai;
  }
  return r;
}

}  // namespace ds1928::endat::wire
