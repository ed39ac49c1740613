#include "powerlink/pdo_image.hpp"

#include <algorithm>
#include <cstdio>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink {
namespace {

// What the scheme says an object is: the slot, whether an input, and the register (a fixed one,
// or an Rx/Tx byte with its number).
struct SchemeHit {
  uint8_t slot = 0;
  bool input = true;
  const SchemeRegister* fixed = nullptr;
  uint8_t byte_no = 0;  // 1-based Rx/Tx byte
};

std::optional<SchemeHit> lookup(const ObjectScheme& scheme, uint16_t index, uint8_t sub) {
  auto in_range = [index](uint16_t base) {
    return index > base && index <= base + kMaxModulesPerNode;
  };
  SchemeHit h;
  h.input = in_range(scheme.input_index);
  if (!h.input && !in_range(scheme.output_index)) return std::nullopt;
  h.slot = static_cast<uint8_t>(index - (h.input ? scheme.input_index : scheme.output_index));
  const std::span<const SchemeRegister> table =
      h.input ? std::span<const SchemeRegister>(kSchemeInputs) : kSchemeOutputs;
  const uint8_t first_byte = h.input ? kSchemeRxByteFirstSub : kSchemeTxByteFirstSub;
  for (const SchemeRegister& r : table)
    if (r.subindex == sub) h.fixed = &r;
  if (h.input)
    for (const SchemeRegister& r : kSchemeInfoInputs)
      if (r.subindex == sub) h.fixed = &r;
  if (!h.fixed && sub >= first_byte && sub < first_byte + kMaxFlatstreamMtu)
    h.byte_no = static_cast<uint8_t>(sub - first_byte + 1);
  if (!h.fixed && h.byte_no == 0) return std::nullopt;
  return h;
}

// One direction's entries into the modules' offsets; false with `issue` set on a bad entry.
bool place(std::span<const PdoMapEntry> entries, uint16_t mapping_index, bool pres,
           const ObjectScheme& scheme, NodeImageLayout& layout, PdoBindIssue& issue) noexcept {
  for (std::size_t k = 0; k < entries.size(); ++k) {
    const PdoMapEntry& e = entries[k];
    // Named without allocating: the MN binds a mapping it read on the cycle thread.
    auto refuse = [&](auto&&... why) {
      issue.error = make_error_code(MnError::kPdoMappingEntryInvalid);
      issue.slot = 0;
      issue.what.clear();
      issue.what.object(mapping_index, static_cast<unsigned>(k + 1)) << " (";
      issue.what.object(e.index, e.subindex) << "): ";
      (issue.what << ... << why);
      return false;
    };
    if (e.length_bits == 0 || e.length_bits % 8 != 0)
      return refuse("length ", unsigned{e.length_bits}, " bits is no whole number of bytes");
    if (e.offset_bits % 8 != 0)
      return refuse("offset ", unsigned{e.offset_bits}, " bits is no whole byte");
    const std::size_t offset = e.offset_bits / 8, bytes = e.length_bits / 8;
    if (offset + bytes > kMaxIsoPayload)
      return refuse("ends at byte ", static_cast<unsigned>(offset + bytes), ", past the ",
                    static_cast<unsigned>(kMaxIsoPayload), "-byte payload");
    const auto hit = lookup(scheme, e.index, e.subindex);
    if (!hit) continue;  // not a register of a module of this scheme
    if (hit->input != pres)
      return refuse(hit->input ? "an input" : "an output", " object mapped into the ",
                    pres ? "PRes" : "PReq");
    ModuleMapping* m = nullptr;
    for (std::size_t i = 0; i < layout.count; ++i)
      if (layout.modules[i].slot == hit->slot) m = &layout.modules[i];
    if (m == nullptr) continue;  // a slot without a configured axis
    const std::size_t want = hit->fixed ? hit->fixed->bytes : 1;
    if (bytes != want)
      return refuse("length ", static_cast<unsigned>(bytes), " bytes, the register has ",
                    static_cast<unsigned>(want));
    const auto off = static_cast<uint16_t>(offset);
    if (hit->fixed) {
      m->fields.fixed[static_cast<std::size_t>(hit->fixed->field)] = off;
    } else if (hit->input) {
      m->fields.rx[hit->byte_no - 1] = off;
    } else {
      m->fields.tx[hit->byte_no - 1] = off;
    }
    uint16_t& end = pres ? m->fields.pres_end : m->fields.preq_end;
    end = std::max<uint16_t>(end, static_cast<uint16_t>(offset + bytes));
  }
  return true;
}

}  // namespace

std::optional<NodeImageLayout> bind_pdo_mapping(const PdoMappingLists& lists,
                                                const ObjectScheme& scheme,
                                                std::span<const ModuleSpec> modules,
                                                PdoBindIssue& issue) noexcept {
  NodeImageLayout layout;
  for (const ModuleSpec& s : modules) {
    if (layout.count == kMaxModulesPerNode || s.input_mtu > kMaxFlatstreamMtu ||
        s.output_mtu > kMaxFlatstreamMtu) {
      issue.error = make_error_code(MnError::kInvalidLayout);
      issue.slot = s.slot;
      issue.what.clear();
      issue.what << "slot " << unsigned{s.slot};
      return std::nullopt;
    }
    ModuleMapping& m = layout.modules[layout.count++];
    m.slot = s.slot;
    m.input_mtu = s.input_mtu;
    m.output_mtu = s.output_mtu;
    m.by_fields = true;
    m.fields = FieldOffsets{};
  }
  if (!place(lists.tpdo, lists.tpdo_index, true, scheme, layout, issue)) return std::nullopt;
  if (!place(lists.rpdo, lists.rpdo_index, false, scheme, layout, issue)) return std::nullopt;
  for (std::size_t i = 0; i < layout.count; ++i) {
    ModuleMapping& m = layout.modules[i];
    // `byte_no` > 0 names an Rx/Tx byte register: `reg` then is its prefix.
    auto missing = [&](std::string_view reg, uint16_t index, uint8_t sub, unsigned byte_no = 0) {
      issue.error = make_error_code(MnError::kPdoRegisterNotMapped);
      issue.slot = m.slot;
      issue.what.clear();
      issue.what << "slot " << unsigned{m.slot} << ": " << reg;
      if (byte_no > 0) issue.what << byte_no;
      issue.what << " (";
      issue.what.object(index, sub) << ") is not mapped";
      return std::nullopt;
    };
    const uint16_t in_obj = static_cast<uint16_t>(scheme.input_index + m.slot);
    const uint16_t out_obj = static_cast<uint16_t>(scheme.output_index + m.slot);
    for (const SchemeRegister& r : kSchemeInputs) {
      if (lists.outputs_only) break;
      const bool needed = r.field != ImageField::kSdcLifeCount &&
                          (r.field != ImageField::kInputSequence || m.input_mtu > 0);
      if (needed && m.fields.fixed[static_cast<std::size_t>(r.field)] == kNotMapped)
        return missing(r.name, in_obj, r.subindex);
    }
    for (uint8_t b = 0; b < m.input_mtu && !lists.outputs_only; ++b)
      if (m.fields.rx[b] == kNotMapped)
        return missing("RxByte", in_obj, static_cast<uint8_t>(kSchemeRxByteFirstSub + b), b + 1u);
    if (m.output_mtu > 0) {
      for (const SchemeRegister& r : kSchemeOutputs)
        if (m.fields.fixed[static_cast<std::size_t>(r.field)] == kNotMapped)
          return missing(r.name, out_obj, r.subindex);
      for (uint8_t b = 0; b < m.output_mtu; ++b)
        if (m.fields.tx[b] == kNotMapped)
          return missing("TxByte", out_obj, static_cast<uint8_t>(kSchemeTxByteFirstSub + b),
                         b + 1u);
    }
    // The first byte of each direction (messages name the module's bytes from there).
    uint16_t first_in = m.fields.pres_end, first_out = m.fields.preq_end;
    for (std::size_t f = 0; f < kImageFieldCount; ++f) {
      const uint16_t at = m.fields.fixed[f];
      if (at == kNotMapped) continue;
      const bool out = f == static_cast<std::size_t>(ImageField::kOutputSequence) ||
                       f == static_cast<std::size_t>(ImageField::kAckErrorInfo);
      (out ? first_out : first_in) = std::min(out ? first_out : first_in, at);
    }
    for (uint16_t at : m.fields.rx) first_in = std::min(first_in, at);
    for (uint16_t at : m.fields.tx) first_out = std::min(first_out, at);
    m.pres_offset = first_in;
    m.preq_offset = first_out;
    layout.pres_size = std::max(layout.pres_size, m.fields.pres_end);
    layout.preq_size = std::max(layout.preq_size, m.fields.preq_end);
  }
  return layout;
}

std::optional<std::vector<PdoMapEntry>> mapping_from_objects(std::span<const CdcEntry> objects,
                                                             uint16_t mapping_index) {
  const CdcEntry* count_entry = find_cdc_entry(objects, mapping_index, 0);
  const auto count = count_entry ? count_entry->as_unsigned() : std::nullopt;
  if (!count) return std::nullopt;
  std::vector<PdoMapEntry> out;
  for (uint64_t s = 1; s <= *count && s <= 254; ++s) {
    const CdcEntry* e = find_cdc_entry(objects, mapping_index, static_cast<uint8_t>(s));
    const auto v = e ? e->as_unsigned() : std::nullopt;
    out.push_back(v ? PdoMapEntry::from_u64(*v) : PdoMapEntry{});
  }
  return out;
}

namespace {
PdoMapEntry entry(uint16_t index, uint8_t sub, std::size_t offset, std::size_t bytes) {
  return {index, sub, static_cast<uint16_t>(offset * 8), static_cast<uint16_t>(bytes * 8)};
}
}  // namespace

std::vector<PdoMapEntry> tpdo_mapping_of(const NodeImageLayout& layout,
                                         const ObjectScheme& scheme) {
  std::vector<PdoMapEntry> out;
  for (const ModuleMapping& m : layout.mappings()) {
    const auto obj = static_cast<uint16_t>(scheme.input_index + m.slot);
    std::size_t at = m.pres_offset;
    for (const SchemeRegister& r : kSchemeInputs) {
      out.push_back(entry(obj, r.subindex, at, r.bytes));
      at += r.bytes;
    }
    for (uint8_t b = 0; b < m.input_mtu; ++b)
      out.push_back(entry(obj, static_cast<uint8_t>(kSchemeRxByteFirstSub + b), at++, 1));
  }
  return out;
}

std::vector<PdoMapEntry> rpdo_mapping_of(const NodeImageLayout& layout, const ObjectScheme& scheme,
                                         uint16_t base) {
  std::vector<PdoMapEntry> out;
  for (const ModuleMapping& m : layout.mappings()) {
    const auto obj = static_cast<uint16_t>(scheme.output_index + m.slot);
    // Where the layout has each output register: the PDO mapping's offsets, or the packed PReq
    // block OutputSequence | TxBytes | AckErrorInfo.
    auto at = [&](ImageField f, std::size_t packed) -> std::size_t {
      return m.by_fields ? m.fields.fixed[static_cast<std::size_t>(f)] : m.preq_offset + packed;
    };
    auto tx_at = [&](uint8_t b) -> std::size_t {
      return m.by_fields ? m.fields.tx[b] : std::size_t{m.preq_offset} + 1 + b;
    };
    if (m.by_fields && m.output_mtu == 0 &&
        m.fields.fixed[static_cast<std::size_t>(ImageField::kOutputSequence)] == kNotMapped)
      continue;  // a module whose mapping carries no outputs
    out.push_back(
        entry(obj, kSchemeOutputs[0].subindex, base + at(ImageField::kOutputSequence, 0), 1));
    for (uint8_t b = 0; b < m.output_mtu; ++b)
      out.push_back(
          entry(obj, static_cast<uint8_t>(kSchemeTxByteFirstSub + b), base + tx_at(b), 1));
    out.push_back(entry(obj, kSchemeOutputs[1].subindex,
                        base + at(ImageField::kAckErrorInfo, std::size_t{1} + m.output_mtu), 1));
  }
  return out;
}

}  // namespace ds1928::powerlink
