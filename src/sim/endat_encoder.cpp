#include "sim/endat_encoder.hpp"

#include <algorithm>
#include <cmath>

#include "endat/names.hpp"

namespace ds1928::sim {

using endat::CommandSet;
using endat::wire::AdditionalInfo;
using endat::wire::BitFrame;
using endat::wire::Mode;

namespace {

constexpr uint8_t kStatusMrs = 0xB9;

}  // namespace

EncoderArea make_encoder_area(uint8_t words_per_block, uint8_t blocks, bool writable) {
  EncoderArea a;
  a.words_per_block = words_per_block;
  a.blocks = blocks;
  a.writable = writable;
  a.words.assign(static_cast<std::size_t>(words_per_block) * blocks, 0);
  return a;
}

unsigned EncoderDescription::effective_position_bits() const noexcept {
  if (position_bits != 0) return position_bits;
  if (type == endat::EncoderType::Rotary) {
    return endat::bits_for(steps_per_revolution) + endat::bits_for(revolutions);
  }
  return 32;
}

void apply_identification(EncoderDescription& d) {
  endat::ManufacturerWords w{};
  for (unsigned page = 0; page < 3; ++page) {
    const auto it = d.areas.find(static_cast<uint8_t>(0xA1 + 2 * page));
    if (it == d.areas.end()) continue;
    for (unsigned i = 0; i < 16 && i < it->second.words.size(); ++i)
      w[page * 16 + i] = it->second.words[i];
  }
  endat::Identification id;
  id.version_word = d.version_word != 0 ? d.version_word
                                        : (d.command_set == CommandSet::EnDat22 ? uint16_t{0x0022}
                                                                                : uint16_t{0x0021});
  id.command_set_word = w[endat::manuf_word::kCommandSet];
  id.command_set = d.command_set;
  id.type = d.type;
  id.position_bits = d.effective_position_bits();
  id.signal_periods = d.signal_periods;
  id.revolutions = d.type == endat::EncoderType::Rotary ? d.revolutions : uint16_t{0};
  id.steps_per_revolution = d.steps_per_revolution;
  id.id = d.id_number;
  id.serial = d.serial_number;
  id.warnings_supported = d.warnings_supported;
  endat::encode_identification(id, w);
  uint16_t sum = 0;
  for (unsigned i = 0; i < endat::manuf_word::kChecksum; ++i)
    sum = static_cast<uint16_t>(sum + w[i]);
  w[endat::manuf_word::kChecksum] = static_cast<uint16_t>(0u - sum);
  for (unsigned page = 0; page < 3; ++page) {
    auto& area = d.areas[static_cast<uint8_t>(0xA1 + 2 * page)];
    if (area.words.size() < 16) area = make_encoder_area(16, 1, area.writable);
    for (unsigned i = 0; i < 16; ++i) area.words[i] = w[page * 16 + i];
  }
}

EncoderDescription default_encoder_description() {
  EncoderDescription d;
  for (uint8_t mrs : {0xA1, 0xA3, 0xA5}) d.areas[mrs] = make_encoder_area(16, 1, false);
  d.areas[0xA7] = make_encoder_area(16, 1, false);
  for (uint8_t mrs : {0xA9, 0xAB, 0xAD, 0xAF}) d.areas[mrs] = make_encoder_area(16, 1, true);
  for (uint8_t mrs : {0xB1, 0xB3, 0xB5, 0xB7}) d.areas[mrs] = make_encoder_area(16, 4, false);
  d.areas[kStatusMrs] = make_encoder_area(4, 1, false);
  d.areas[0xBB] = make_encoder_area(16, 1, false);
  d.areas[0xBD] = make_encoder_area(64, 1, false);
  d.areas[0xBF] = make_encoder_area(16, 1, false);
  // Operating parameter word 6: temperature warning threshold, 85 °C.
  d.areas[0xA7].words[6] = endat::temperature_raw(85.0);
  apply_identification(d);
  return d;
}

// ---------------------------------------------------------------------------------------------
// Encoder

EnDatEncoder::EnDatEncoder(EncoderDescription description)
    : description_(std::move(description)), rng_(description_.faults.seed) {
  position_bits_ =
      std::clamp(description_.effective_position_bits(), 1u, endat::wire::kMaxPositionBits);
}

uint64_t EnDatEncoder::position_mask() const noexcept {
  return position_bits_ >= 64 ? ~uint64_t{0} : (uint64_t{1} << position_bits_) - 1;
}

int64_t EnDatEncoder::scaled(int64_t ns) const noexcept {
  return static_cast<int64_t>(std::llround(static_cast<double>(ns) * description_.timing.scale));
}

std::optional<uint16_t> EnDatEncoder::word(uint8_t mrs, uint8_t block, uint8_t param) const {
  const auto it = description_.areas.find(mrs);
  if (it == description_.areas.end()) return std::nullopt;
  const auto& a = it->second;
  if (block >= a.blocks || param >= a.words_per_block) return std::nullopt;
  return a.words[static_cast<std::size_t>(block) * a.words_per_block + param];
}

bool EnDatEncoder::set_word(uint8_t mrs, uint8_t block, uint8_t param, uint16_t value) {
  const auto it = description_.areas.find(mrs);
  if (it == description_.areas.end()) return false;
  auto& a = it->second;
  if (block >= a.blocks || param >= a.words_per_block) return false;
  a.words[static_cast<std::size_t>(block) * a.words_per_block + param] = value;
  return true;
}

uint16_t* EnDatEncoder::status_word(unsigned index) {
  auto it = description_.areas.find(kStatusMrs);
  if (it == description_.areas.end() || index >= it->second.words.size()) return nullptr;
  return &it->second.words[index];
}

uint16_t EnDatEncoder::error_word() const {
  return word(kStatusMrs, 0, 0).value_or(0);
}
uint16_t EnDatEncoder::warning_word() const {
  return word(kStatusMrs, 0, 1).value_or(0);
}

// Conditions that persist set their status bits again after every clear, like a real encoder
// that re-detects a weak battery.
void EnDatEncoder::apply_conditions() {
  const auto& f = description_.faults;
  if (auto* e = status_word(0)) {
    if (f.position_error) *e |= 0x0004;
    if (f.battery_error) *e |= 0x0040;
    *e |= f.error_bits;
  }
  if (auto* w = status_word(1)) {
    if (f.battery_warning) *w |= 0x0008;
    *w |= f.warning_bits;
  }
}

void EnDatEncoder::set_error_conditions(uint16_t bits) noexcept {
  description_.faults.error_bits = bits;
  apply_conditions();
}

void EnDatEncoder::set_warning_conditions(uint16_t bits) noexcept {
  description_.faults.warning_bits = bits;
  apply_conditions();
}

void EnDatEncoder::reset_state() {
  selection_.reset();
  ai1_.reset();
  ai2_.reset();
  if (auto* e = status_word(0)) *e = 0;
  if (auto* w = status_word(1)) *w = 0;
}

uint16_t EnDatEncoder::info_data(uint8_t code) const {
  const uint64_t p = position_;
  const uint64_t p2 = position2_.value_or(position_);
  switch (code) {
    case 0x41:
      return 100;  // diagnosis: function reserve in percent
    case 0x42:
      return static_cast<uint16_t>(p2 & 0xFFFF);
    case 0x56:
      return static_cast<uint16_t>(p & 0xFFFF);
    case 0x43:
      return static_cast<uint16_t>((p2 >> 16) & 0xFFFF);
    case 0x57:
      return static_cast<uint16_t>((p >> 16) & 0xFFFF);
    case 0x44:
      return static_cast<uint16_t>((p2 >> 32) & 0xFFFF);
    case 0x58:
      return static_cast<uint16_t>((p >> 32) & 0xFFFF);
    case 0x47:
      return selection_ ? static_cast<uint16_t>(selection_->mrs << 8 | selection_->block) : 0;
    case 0x4C:
      return endat::temperature_raw(description_.temperature_c);
    case 0x4D:
      return endat::temperature_raw(description_.temperature2_c);
    case 0x51: {  // commutation: top 16 bits of the position within one revolution
      const unsigned st = endat::bits_for(description_.steps_per_revolution);
      const uint64_t in_rev =
          description_.steps_per_revolution ? p % description_.steps_per_revolution : p;
      return static_cast<uint16_t>(st > 16 ? in_rev >> (st - 16) : in_rev << (16 - st));
    }
    case 0x59:
      return error_word();
    case 0x5B:
      return static_cast<uint16_t>(frames_ & 0xFFFF);
    default:
      return 0;
  }
}

std::optional<AdditionalInfo> EnDatEncoder::next_info(std::optional<InfoSelection>& sel, uint64_t) {
  if (!sel) return std::nullopt;
  AdditionalInfo ai;
  ai.status = static_cast<uint8_t>(sel->code & 0x1F);
  if (warning_word() != 0) ai.status |= 0x80;
  if (sel->busy_frames > 0) {
    --sel->busy_frames;
    ai.status |= 0x20;
    return ai;
  }
  ai.data = info_data(sel->code);
  return ai;
}

BitFrame EnDatEncoder::position_frame(bool endat22) {
  ++frames_;
  endat::wire::PositionReply r;
  r.f1 = error_word() != 0;
  r.f2 = !r.f1;
  r.position = position_;
  if (endat22) {
    r.ai1 = next_info(ai1_, frames_);
    r.ai2 = next_info(ai2_, frames_);
  }
  return endat::wire::encode_position_reply(r, endat22 ? CommandSet::EnDat22 : CommandSet::EnDat21,
                                            position_bits_);
}

void EnDatEncoder::finish(BitFrame& reply) {
  if (reply.size() < 2) return;
  bool corrupt = false;
  if (forced_crc_errors_ > 0) {
    --forced_crc_errors_;
    corrupt = true;
  } else if (description_.faults.crc_error_rate > 0.0) {
    corrupt = static_cast<double>(rng_()) / 4294967296.0 < description_.faults.crc_error_rate;
  }
  if (corrupt) {
    reply.flip(1 + rng_() % (reply.size() - 1));  // never the start bit
    ++corrupted_;
  }
}

EncoderResponse EnDatEncoder::transact(const BitFrame& master, int64_t now_ns) {
  ++transactions_;
  EncoderResponse out;
  if (forced_silence_ > 0) {
    --forced_silence_;
    return out;
  }
  if (now_ns < deaf_until_ns_) return out;
  const auto frame = endat::wire::decode_master_frame(master);
  if (!frame) return out;
  const bool v22 = description_.command_set == CommandSet::EnDat22;
  if (endat::wire::is_endat22_mode(frame->mode) && !v22) return out;
  apply_conditions();

  const auto& t = description_.timing;
  switch (frame->mode) {
    case Mode::SendPosition:
      out.reply = position_frame(false);
      break;
    case Mode::PositionAddInfo:
      out.reply = position_frame(true);
      break;
    case Mode::SelectMemoryArea: {
      const auto it = description_.areas.find(frame->address);
      if (it == description_.areas.end() || frame->parameter >= it->second.blocks) {
        selection_.reset();
        return out;
      }
      selection_ = Selection{frame->address, static_cast<uint8_t>(frame->parameter)};
      out.reply = endat::wire::encode_parameter_reply({frame->address, frame->parameter});
      out.processing_ns = scaled(t.select_memory_ns);
      break;
    }
    case Mode::SendParameter: {
      if (!selection_) return out;
      const auto v = word(selection_->mrs, selection_->block, frame->address);
      if (!v) return out;
      out.reply = endat::wire::encode_parameter_reply({frame->address, *v});
      out.processing_ns = scaled(t.read_parameter_ns);
      break;
    }
    case Mode::ReceiveParameter: {
      if (!selection_ || !word(selection_->mrs, selection_->block, frame->address)) return out;
      const auto& area = description_.areas.at(selection_->mrs);
      if (selection_->mrs == kStatusMrs && frame->address < 2) {
        // Operating status errors/warnings: writing clears the bits written as 0.
        const uint16_t old = *word(kStatusMrs, 0, frame->address);
        set_word(kStatusMrs, 0, frame->address, static_cast<uint16_t>(old & frame->parameter));
      } else if (area.writable) {
        set_word(selection_->mrs, selection_->block, frame->address, frame->parameter);
      }
      // A protected area echoes like any other: the value just does not change.
      out.reply = endat::wire::encode_parameter_reply({frame->address, frame->parameter});
      out.processing_ns = scaled(t.write_parameter_ns);
      break;
    }
    case Mode::ReceiveReset:
      reset_state();
      apply_conditions();
      out.reply = endat::wire::encode_parameter_reply({frame->address, frame->parameter});
      out.processing_ns = scaled(t.reset_ns);
      deaf_until_ns_ = now_ns + out.processing_ns;
      break;
    case Mode::PositionAddInfoSelectMemory: {
      const uint8_t code = frame->address;
      if (code >= 0x40 && code <= 0x4F) {
        if (code == 0x40 || code == 0x4F) {
          ai1_.reset();
        } else {
          ai1_ = InfoSelection{code, 1};
        }
      } else if (code >= 0x50 && code <= 0x5F) {
        if (code == 0x50 || code == 0x5F) {
          ai2_.reset();
        } else {
          ai2_ = InfoSelection{code, 1};
        }
      } else if (const auto it = description_.areas.find(code);
                 it != description_.areas.end() && frame->parameter < it->second.blocks) {
        selection_ = Selection{code, static_cast<uint8_t>(frame->parameter)};
      } else {
        return out;
      }
      out.reply = position_frame(true);
      out.processing_ns = scaled(t.select_info_ns);
      break;
    }
    case Mode::PositionAddInfoErrorReset:
      if (auto* e = status_word(0)) *e = 0;
      if (auto* w = status_word(1)) *w = 0;
      apply_conditions();
      out.reply = position_frame(true);
      out.processing_ns = scaled(t.error_reset_ns);
      break;
    default:
      return out;  // test values, test commands and the 2.2 parameter modes are not modelled
  }
  finish(out.reply);
  return out;
}

}  // namespace ds1928::sim
