#include "sim/cn_object_dictionary.hpp"

#include <algorithm>
#include <cstring>

#include "core/sdo_abort.hpp"
#include "powerlink/concise_dcf.hpp"

namespace ds1928::sim {
namespace {

using powerlink::kStandardObjects;
using powerlink::ObjAccess;
using powerlink::ObjHolder;
using powerlink::ObjType;
using powerlink::StandardObject;
namespace obj = powerlink::obj;

constexpr uint32_t kSignatureSave = 0x65766173;  // "save", little-endian
constexpr uint32_t kSignatureLoad = 0x64616F6C;  // "load"

[[nodiscard]] constexpr bool stored(const StandardObject& o) noexcept {
  return o.holder == ObjHolder::kCn && o.type != ObjType::kDomain;
}
[[nodiscard]] constexpr std::size_t entries(const StandardObject& o) noexcept {
  return std::min<std::size_t>(o.sub_last - o.sub_first + 1u, CnObjectDictionary::kMaxMapped);
}

// The first slot of each row (rows not stored: unused).
constexpr std::array<std::size_t, kStandardObjects.size()> kFirstSlot = [] {
  std::array<std::size_t, kStandardObjects.size()> first{};
  std::size_t n = 0;
  for (std::size_t i = 0; i < kStandardObjects.size(); ++i) {
    first[i] = n;
    if (stored(kStandardObjects[i])) n += entries(kStandardObjects[i]);
  }
  return first;
}();

uint64_t le(std::span<const uint8_t> d) noexcept {
  uint64_t v = 0;
  for (std::size_t i = 0; i < d.size() && i < 8; ++i) v |= static_cast<uint64_t>(d[i]) << (8 * i);
  return v;
}

// The CN row of index/subindex; `abort` says why there is none.
const StandardObject* cn_row(uint16_t index, uint8_t sub, std::size_t& row_no,
                             uint32_t& abort) noexcept {
  abort = sdo_abort::kNoObject;
  for (std::size_t i = 0; i < kStandardObjects.size(); ++i) {
    const StandardObject& o = kStandardObjects[i];
    if (o.index != index || o.holder != ObjHolder::kCn) continue;
    abort = sdo_abort::kNoSubindex;
    if (sub < o.sub_first || sub > o.sub_last) continue;
    if (o.type != ObjType::kDomain && std::size_t{sub} - o.sub_first >= entries(o))
      continue;  // beyond the simulated device's capacity
    row_no = i;
    abort = 0;
    return &o;
  }
  return nullptr;
}

}  // namespace

CnObjectDictionary::CnObjectDictionary() noexcept {
  for (std::size_t i = 0; i < kStandardObjects.size(); ++i) {
    if (!stored(kStandardObjects[i])) continue;
    for (std::size_t k = 0; k < entries(kStandardObjects[i]); ++k)
      v_.slot[kFirstSlot[i] + k] = kStandardObjects[i].default_value;
  }
  factory_ = v_;
  stored_ = v_;
}

bool CnObjectDictionary::set_own_mapping(uint16_t mapping_index,
                                         std::span<const powerlink::PdoMapEntry> entries) noexcept {
  if (entries.size() > kMaxMapped) return false;
  set(mapping_index, 0, entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i)
    set(mapping_index, static_cast<uint8_t>(i + 1), entries[i].to_u64());
  factory_ = v_;
  return true;
}

bool CnObjectDictionary::handles(uint16_t index) noexcept {
  return powerlink::has_standard_index(index, ObjHolder::kCn);
}

const uint64_t* CnObjectDictionary::find(uint16_t index, uint8_t sub, const StandardObject*& row,
                                         uint32_t& abort) const noexcept {
  std::size_t i = 0;
  row = cn_row(index, sub, i, abort);
  if (!row || row->type == ObjType::kDomain) return nullptr;
  return &v_.slot[kFirstSlot[i] + (sub - row->sub_first)];
}

uint64_t CnObjectDictionary::value(uint16_t index, uint8_t sub) const noexcept {
  const StandardObject* row = nullptr;
  uint32_t abort = 0;
  const uint64_t* v = find(index, sub, row, abort);
  return v ? *v : 0;
}

void CnObjectDictionary::set(uint16_t index, uint8_t sub, uint64_t value) noexcept {
  const StandardObject* row = nullptr;
  uint32_t abort = 0;
  if (const uint64_t* v = find(index, sub, row, abort)) *const_cast<uint64_t*>(v) = value;
}

uint32_t CnObjectDictionary::read(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                                  std::size_t& size) const noexcept {
  const StandardObject* row = nullptr;
  uint32_t abort = 0;
  const uint64_t* v = find(index, sub, row, abort);
  if (!row) return abort;
  if (row->type == ObjType::kDomain) {
    if (out.size() < v_.dcf_size) return sdo_abort::kGeneral;
    std::memcpy(out.data(), v_.dcf.data(), v_.dcf_size);
    size = v_.dcf_size;
    return 0;
  }
  const std::size_t width = powerlink::type_size(row->type);
  if (out.size() < width) return sdo_abort::kGeneral;
  for (std::size_t i = 0; i < width; ++i) out[i] = static_cast<uint8_t>(*v >> (8 * i));
  size = width;
  return 0;
}

uint32_t CnObjectDictionary::write(uint16_t index, uint8_t sub,
                                   std::span<const uint8_t> data) noexcept {
  const StandardObject* row = nullptr;
  uint32_t abort = 0;
  const uint64_t* slot = find(index, sub, row, abort);
  if (!row) return abort;
  if (row->access != ObjAccess::kRw) return sdo_abort::kReadOnly;
  if (row->type == ObjType::kDomain) {
    if (data.size() > kMaxStoredDcf) return sdo_abort::kOutOfRange;
    std::memcpy(v_.dcf.data(), data.data(), data.size());
    v_.dcf_size = data.size();
    return 0;
  }
  if (data.size() != powerlink::type_size(row->type)) return sdo_abort::kTypeLength;
  const uint64_t v = le(data);
  // The rules a type and an access do not say.
  if (index == obj::kStoreParam || index == obj::kRestoreDefParam) {
    // Without the signature ("save" / "load") DS 301 answers "data cannot be transferred or
    // stored". The value itself is not kept (it reads back the device's capability).
    if (index == obj::kStoreParam) {
      if (v != kSignatureSave) return sdo_abort::kCannotStore;
      stored_ = v_;
      has_stored_ = true;
    } else {
      // Defaults again from the next reset on (the values in use stay until then).
      if (v != kSignatureLoad) return sdo_abort::kCannotStore;
      has_stored_ = false;
    }
    return 0;
  }
  if (index == obj::kCycleTiming &&
      (sub == obj::kCycleTimingPReqActPayload || sub == obj::kCycleTimingPResActPayload)) {
    // The payload in use is at most the device's limit (/2 for the PReq, /1 for the PRes).
    if (v > value(obj::kCycleTiming, sub == obj::kCycleTimingPReqActPayload ? 2 : 1))
      return sdo_abort::kOutOfRange;
  }
  if (index == obj::kRxPdoMapping || index == obj::kRxPdoMappingPresMn ||
      index == obj::kTxPdoMapping) {
    if (sub == 0 && v > kMaxMapped) return sdo_abort::kOutOfRange;
    // Mapping written while enabled (sub 0 ≠ 0): DS 301 wants it disabled first.
    if (sub != 0 && value(index, 0) != 0) return sdo_abort::kDeviceState;
  }
  *const_cast<uint64_t*>(slot) = v;
  return 0;
}

void CnObjectDictionary::set_identity(uint32_t device_type, uint32_t vendor_id,
                                      uint32_t product_code, uint32_t revision_no,
                                      uint32_t serial_no) noexcept {
  set(obj::kDeviceType, 0, device_type);
  set(obj::kIdentity, 1, vendor_id);
  set(obj::kIdentity, 2, product_code);
  set(obj::kIdentity, 3, revision_no);
  set(obj::kIdentity, 4, serial_no);
}

void CnObjectDictionary::set_error_register(uint8_t bits) noexcept {
  set(obj::kErrorRegister, 0, bits);
}

void CnObjectDictionary::reset_communication() noexcept {
  // The written values return to the stored (or default) ones; the device's own stay.
  const Values& from = has_stored_ ? stored_ : factory_;
  for (std::size_t i = 0; i < kStandardObjects.size(); ++i) {
    const StandardObject& o = kStandardObjects[i];
    if (!stored(o) || o.access != ObjAccess::kRw) continue;
    for (std::size_t k = 0; k < entries(o); ++k)
      v_.slot[kFirstSlot[i] + k] = from.slot[kFirstSlot[i] + k];
  }
  v_.dcf = from.dcf;
  v_.dcf_size = from.dcf_size;
}

uint16_t CnObjectDictionary::mapped_end_bytes(uint16_t mapping_index) const noexcept {
  uint32_t end_bits = 0;
  const auto count = static_cast<uint8_t>(value(mapping_index, 0));
  for (uint8_t i = 1; i <= count; ++i) {
    const auto e = powerlink::PdoMapEntry::from_u64(value(mapping_index, i));
    end_bits = std::max<uint32_t>(end_bits, uint32_t{e.offset_bits} + e.length_bits);
  }
  return static_cast<uint16_t>((end_bits + 7) / 8);
}

std::size_t CnObjectDictionary::mapping(uint16_t mapping_index,
                                        std::span<powerlink::PdoMapEntry> out) const noexcept {
  const std::size_t count =
      std::min<std::size_t>(static_cast<uint8_t>(value(mapping_index, 0)), out.size());
  for (std::size_t i = 0; i < count; ++i)
    out[i] = powerlink::PdoMapEntry::from_u64(value(mapping_index, static_cast<uint8_t>(i + 1)));
  return count;
}

uint16_t CnObjectDictionary::pres_size(uint16_t fallback) const noexcept {
  if (const auto v = value(obj::kCycleTiming, obj::kCycleTimingPResActPayload); v != 0)
    return static_cast<uint16_t>(v);
  if (value(obj::kTxPdoMapping, 0) != 0)
    return std::max(fallback, mapped_end_bytes(obj::kTxPdoMapping));
  return fallback;
}

uint16_t CnObjectDictionary::preq_size(uint16_t fallback) const noexcept {
  if (const auto v = value(obj::kCycleTiming, obj::kCycleTimingPReqActPayload); v != 0)
    return static_cast<uint16_t>(v);
  if (value(obj::kRxPdoMapping, 0) != 0)
    return std::max(fallback, mapped_end_bytes(obj::kRxPdoMapping));
  return fallback;
}

uint8_t CnObjectDictionary::rpdo_source(uint16_t comm_index) const noexcept {
  return static_cast<uint8_t>(value(comm_index, 1));
}
uint32_t CnObjectDictionary::cycle_length_us() const noexcept {
  return static_cast<uint32_t>(value(obj::kCycleLen, 0));
}
uint8_t CnObjectDictionary::multiplexed_cycle_count() const noexcept {
  return static_cast<uint8_t>(value(obj::kCycleTiming, obj::kCycleTimingMultiplCycleCnt));
}
uint32_t CnObjectDictionary::loss_of_frame_tolerance_ns() const noexcept {
  return static_cast<uint32_t>(value(obj::kLossOfSocTolerance, 0));
}
uint32_t CnObjectDictionary::configuration_date() const noexcept {
  return static_cast<uint32_t>(value(obj::kVerifyConfiguration, 1));
}
uint32_t CnObjectDictionary::configuration_time() const noexcept {
  return static_cast<uint32_t>(value(obj::kVerifyConfiguration, 2));
}

}  // namespace ds1928::sim
