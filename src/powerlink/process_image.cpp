#include "powerlink/process_image.hpp"

#include <algorithm>
#include <cstring>

#include "powerlink/frames.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::powerlink {

Result<NodeImageLayout> make_layout(std::span<const ModuleSpec> modules,
                                    LayoutIssue* issue) noexcept {
  auto fail = [issue](MnError e, uint8_t slot, uint8_t other, bool in_preq) {
    if (issue) *issue = {slot, other, in_preq};
    return e;
  };
  if (modules.size() > kMaxModulesPerNode) return fail(MnError::kInvalidLayout, 0, 0, false);
  std::array<ModuleSpec, kMaxModulesPerNode> sorted{};
  std::copy(modules.begin(), modules.end(), sorted.begin());
  std::sort(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(modules.size()),
            [](const ModuleSpec& a, const ModuleSpec& b) { return a.slot < b.slot; });
  NodeImageLayout layout;
  std::size_t packed_pres = 0;
  std::size_t packed_preq = 0;
  std::size_t pres_end = 0;
  std::size_t preq_end = 0;
  for (std::size_t i = 0; i < modules.size(); ++i) {
    const ModuleSpec& s = sorted[i];
    if (s.slot == 0 || (i > 0 && sorted[i - 1].slot == s.slot))
      return fail(MnError::kInvalidLayout, s.slot, i > 0 ? sorted[i - 1].slot : 0, false);
    if (s.input_mtu > kMaxFlatstreamMtu || s.output_mtu > kMaxFlatstreamMtu)
      return fail(MnError::kInvalidLayout, s.slot, 0, s.output_mtu > kMaxFlatstreamMtu);
    // Default offsets are those of the all-default layout, whatever the overrides.
    const std::size_t pres = s.pres_offset.value_or(static_cast<uint16_t>(packed_pres));
    const std::size_t preq = s.preq_offset.value_or(static_cast<uint16_t>(packed_preq));
    packed_pres += pres_module_size(s.input_mtu);
    packed_preq += preq_module_size(s.output_mtu);
    if (pres + pres_module_size(s.input_mtu) > kMaxIsoPayload)
      return fail(MnError::kModuleBlockOutsidePayload, s.slot, 0, false);
    if (preq + preq_module_size(s.output_mtu) > kMaxIsoPayload)
      return fail(MnError::kModuleBlockOutsidePayload, s.slot, 0, true);
    ModuleMapping m;
    m.slot = s.slot;
    m.input_mtu = s.input_mtu;
    m.output_mtu = s.output_mtu;
    m.pres_offset = static_cast<uint16_t>(pres);
    m.preq_offset = static_cast<uint16_t>(preq);
    for (std::size_t j = 0; j < i; ++j) {
      const ModuleMapping& o = layout.modules[j];
      if (m.pres_offset < o.pres_offset + pres_module_size(o.input_mtu) &&
          o.pres_offset < m.pres_offset + pres_module_size(m.input_mtu))
        return fail(MnError::kModuleBlocksOverlap, s.slot, o.slot, false);
      if (m.preq_offset < o.preq_offset + preq_module_size(o.output_mtu) &&
          o.preq_offset < m.preq_offset + preq_module_size(m.output_mtu))
        return fail(MnError::kModuleBlocksOverlap, s.slot, o.slot, true);
    }
    layout.modules[i] = m;
    pres_end = std::max(pres_end, pres + pres_module_size(s.input_mtu));
    preq_end = std::max(preq_end, preq + preq_module_size(s.output_mtu));
  }
  layout.count = modules.size();
  layout.pres_size = static_cast<uint16_t>(pres_end);
  layout.preq_size = static_cast<uint16_t>(preq_end);
  return layout;
}

namespace {

// Registers at the offsets of the CN's PDO mapping (fields already checked to lie below pres_end
// / preq_end, which the caller compared with the payload).
template <class T>
void put(uint8_t* p, uint16_t at, T v) noexcept {
  if (at == kNotMapped) return;
  if constexpr (sizeof(T) == 4) {
    store_le32(p + at, static_cast<uint32_t>(v));
  } else {
    p[at] = static_cast<uint8_t>(v);
  }
}
uint32_t get32(const uint8_t* p, uint16_t at) noexcept {
  return at == kNotMapped ? 0 : load_le32(p + at);
}
uint8_t get8(const uint8_t* p, uint16_t at) noexcept {
  return at == kNotMapped ? 0 : p[at];
}
uint16_t get16(const uint8_t* p, uint16_t at) noexcept {
  return at == kNotMapped ? 0 : static_cast<uint16_t>(p[at] | p[at + 1] << 8);
}
void put16(uint8_t* p, uint16_t at, uint16_t v) noexcept {
  if (at == kNotMapped) return;
  p[at] = static_cast<uint8_t>(v);
  p[at + 1] = static_cast<uint8_t>(v >> 8);
}
constexpr std::array<ImageField, 4> kInfoFields{ImageField::kInfo1, ImageField::kInfo2,
                                                ImageField::kInfo3, ImageField::kInfo4};
constexpr std::size_t f(ImageField x) noexcept {
  return static_cast<std::size_t>(x);
}

}  // namespace

bool write_inputs(std::span<uint8_t> payload, const ModuleMapping& m,
                  const ModuleInputs& in) noexcept {
  if (m.by_fields) {
    const FieldOffsets& o = m.fields;
    if (o.pres_end > payload.size()) return false;
    uint8_t* p = payload.data();
    put(p, o.fixed[f(ImageField::kPositionHW)], in.position_hw);
    put(p, o.fixed[f(ImageField::kPositionLW)], in.position_lw);
    put(p, o.fixed[f(ImageField::kPosTime)], in.pos_time_us);
    put(p, o.fixed[f(ImageField::kPosCycle)], static_cast<uint8_t>(in.pos_cycle));
    put(p, o.fixed[f(ImageField::kSdcLifeCount)], static_cast<uint8_t>(in.sdc_life_count));
    put(p, o.fixed[f(ImageField::kErrorInfo)], in.error_info);
    put(p, o.fixed[f(ImageField::kInputSequence)], in.input_sequence);
    for (std::size_t b = 0; b < m.input_mtu; ++b) put(p, o.rx[b], in.rx_bytes[b]);
    put(p, o.fixed[f(ImageField::kInfoOk)], in.info_ok);
    for (std::size_t n = 0; n < kInfoFields.size(); ++n)
      put16(p, o.fixed[f(kInfoFields[n])], in.info[n]);
    return true;
  }
  if (m.pres_offset + pres_module_size(m.input_mtu) > payload.size()) return false;
  uint8_t* p = payload.data() + m.pres_offset;
  store_le32(p + fm0::kPositionHw, in.position_hw);
  store_le32(p + fm0::kPositionLw, in.position_lw);
  store_le32(p + fm0::kPosTime, in.pos_time_us);
  p[fm0::kPosCycle] = static_cast<uint8_t>(in.pos_cycle);
  p[fm0::kSdcLifeCount] = static_cast<uint8_t>(in.sdc_life_count);
  p[fm0::kErrorInfo] = in.error_info;
  p[fm0::kInputSequence] = in.input_sequence;
  std::memcpy(p + fm0::kRxBytes, in.rx_bytes.data(), m.input_mtu);
  return true;
}

bool read_inputs(std::span<const uint8_t> payload, const ModuleMapping& m,
                 ModuleInputs& in) noexcept {
  if (m.by_fields) {
    const FieldOffsets& o = m.fields;
    if (o.pres_end > payload.size()) return false;
    const uint8_t* p = payload.data();
    in.position_hw = get32(p, o.fixed[f(ImageField::kPositionHW)]);
    in.position_lw = get32(p, o.fixed[f(ImageField::kPositionLW)]);
    in.pos_time_us = get32(p, o.fixed[f(ImageField::kPosTime)]);
    in.pos_cycle = static_cast<int8_t>(get8(p, o.fixed[f(ImageField::kPosCycle)]));
    in.sdc_life_count = static_cast<int8_t>(get8(p, o.fixed[f(ImageField::kSdcLifeCount)]));
    in.error_info = get8(p, o.fixed[f(ImageField::kErrorInfo)]);
    in.input_sequence = get8(p, o.fixed[f(ImageField::kInputSequence)]);
    in.rx_bytes.fill(0);
    for (std::size_t b = 0; b < m.input_mtu; ++b) in.rx_bytes[b] = get8(p, o.rx[b]);
    in.info_ok = get8(p, o.fixed[f(ImageField::kInfoOk)]);
    for (std::size_t n = 0; n < kInfoFields.size(); ++n)
      in.info[n] = get16(p, o.fixed[f(kInfoFields[n])]);
    return true;
  }
  if (m.pres_offset + pres_module_size(m.input_mtu) > payload.size()) return false;
  const uint8_t* p = payload.data() + m.pres_offset;
  in.position_hw = load_le32(p + fm0::kPositionHw);
  in.position_lw = load_le32(p + fm0::kPositionLw);
  in.pos_time_us = load_le32(p + fm0::kPosTime);
  in.pos_cycle = static_cast<int8_t>(p[fm0::kPosCycle]);
  in.sdc_life_count = static_cast<int8_t>(p[fm0::kSdcLifeCount]);
  in.error_info = p[fm0::kErrorInfo];
  in.input_sequence = p[fm0::kInputSequence];
  in.rx_bytes.fill(0);
  std::memcpy(in.rx_bytes.data(), p + fm0::kRxBytes, m.input_mtu);
  return true;
}

bool write_outputs(std::span<uint8_t> payload, const ModuleMapping& m,
                   const ModuleOutputs& out) noexcept {
  if (m.by_fields) {
    const FieldOffsets& o = m.fields;
    if (o.preq_end > payload.size()) return false;
    uint8_t* p = payload.data();
    put(p, o.fixed[f(ImageField::kOutputSequence)], out.output_sequence);
    for (std::size_t b = 0; b < m.output_mtu; ++b) put(p, o.tx[b], out.tx_bytes[b]);
    put(p, o.fixed[f(ImageField::kAckErrorInfo)], out.ack_error_info);
    return true;
  }
  if (m.preq_offset + preq_module_size(m.output_mtu) > payload.size()) return false;
  uint8_t* p = payload.data() + m.preq_offset;
  p[fm0::kOutputSequence] = out.output_sequence;
  std::memcpy(p + fm0::kTxBytes, out.tx_bytes.data(), m.output_mtu);
  p[fm0::kTxBytes + m.output_mtu] = out.ack_error_info;
  return true;
}

bool read_outputs(std::span<const uint8_t> payload, const ModuleMapping& m,
                  ModuleOutputs& out) noexcept {
  if (m.by_fields) {
    const FieldOffsets& o = m.fields;
    if (o.preq_end > payload.size()) return false;
    const uint8_t* p = payload.data();
    out.output_sequence = get8(p, o.fixed[f(ImageField::kOutputSequence)]);
    out.tx_bytes.fill(0);
    for (std::size_t b = 0; b < m.output_mtu; ++b) out.tx_bytes[b] = get8(p, o.tx[b]);
    out.ack_error_info = get8(p, o.fixed[f(ImageField::kAckErrorInfo)]);
    return true;
  }
  if (m.preq_offset + preq_module_size(m.output_mtu) > payload.size()) return false;
  const uint8_t* p = payload.data() + m.preq_offset;
  out.output_sequence = p[fm0::kOutputSequence];
  out.tx_bytes.fill(0);
  std::memcpy(out.tx_bytes.data(), p + fm0::kTxBytes, m.output_mtu);
  out.ack_error_info = p[fm0::kTxBytes + m.output_mtu];
  return true;
}

bool preq_overlaps(const ModuleMapping& m, std::size_t lo, std::size_t hi) noexcept {
  auto in = [&](uint16_t at) { return at != kNotMapped && at >= lo && at < hi; };
  if (!m.by_fields) return lo < preq_end(m) && hi > m.preq_offset;
  if (in(m.fields.fixed[static_cast<std::size_t>(ImageField::kOutputSequence)]) ||
      in(m.fields.fixed[static_cast<std::size_t>(ImageField::kAckErrorInfo)]))
    return true;
  for (std::size_t b = 0; b < m.output_mtu; ++b)
    if (in(m.fields.tx[b])) return true;
  return false;
}

}  // namespace ds1928::powerlink
