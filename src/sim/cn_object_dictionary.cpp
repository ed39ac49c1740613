#include "sim/cn_object_dictionary.hpp"

#include <algorithm>
#include <cstring>

#include "core/sdo_abort.hpp"

namespace ds1928::sim {
namespace {

constexpr uint32_t kSignatureSave = 0x65766173;  // "save", little-endian
constexpr uint32_t kSignatureLoad = 0x64616F6C;  // "load"

uint64_t le(std::span<const uint8_t> d) noexcept {
  uint64_t v = 0;
  for (std::size_t i = 0; i < d.size() && i < 8; ++i) v |= static_cast<uint64_t>(d[i]) << (8 * i);
  return v;
}

// A value of `width` bytes into `out`.
uint32_t put(std::span<uint8_t> out, std::size_t& size, uint64_t v, std::size_t width) noexcept {
  if (out.size() < width) return sdo_abort::kGeneral;
  for (std::size_t i = 0; i < width; ++i) out[i] = static_cast<uint8_t>(v >> (8 * i));
  size = width;
  return 0;
}

// Writes `data` of exactly `width` bytes into `field`.
template <class T>
uint32_t take(T& field, std::span<const uint8_t> data) noexcept {
  if (data.size() != sizeof(T)) return sdo_abort::kTypeLength;
  field = static_cast<T>(le(data));
  return 0;
}

}  // namespace

uint16_t CnObjectDictionary::Mapping::end_bytes() const noexcept {
  uint32_t end_bits = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const uint64_t e = entries[i];
    const uint32_t offset = static_cast<uint16_t>(e >> 32);
    const uint32_t length = static_cast<uint16_t>(e >> 48);
    end_bits = std::max(end_bits, offset + length);
  }
  return static_cast<uint16_t>((end_bits + 7) / 8);
}

bool CnObjectDictionary::handles(uint16_t index) noexcept {
  switch (index) {
    case 0x1006:
    case 0x1010:
    case 0x1011:
    case 0x1020:
    case 0x1C0B:
    case 0x1C0C:
    case 0x1C0D:
    case 0x1C0F:
    case 0x1C14:
    case 0x1F98:
    case 0x1400:
    case 0x1800:
    case 0x1600:
    case 0x1A00:
    case 0x1F22:
      return true;
    default:
      return false;
  }
}

uint32_t CnObjectDictionary::read(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                                  std::size_t& size) const noexcept {
  switch (index) {
    case 0x1006:
      return sub == 0 ? put(out, size, v_.cycle_len_us_, 4) : sdo_abort::kNoSubindex;
    case 0x1010:
    case 0x1011:
      // Sub 1 (all parameters): bit 0 = the device saves (restores) on command.
      if (sub == 0) return put(out, size, 1, 1);
      return sub == 1 ? put(out, size, 1, 4) : sdo_abort::kNoSubindex;
    case 0x1C0B:
    case 0x1C0C:
    case 0x1C0D:
    case 0x1C0F: {
      const LossCounter& c = loss_counter(index);
      if (sub == 0) return put(out, size, 3, 1);
      if (sub == 1) return put(out, size, c.cumulative, 4);
      if (sub == 2) return put(out, size, c.threshold_count, 4);
      if (sub == 3) return put(out, size, c.threshold, 4);
      return sdo_abort::kNoSubindex;
    }
    case 0x1020:
      if (sub == 0) return put(out, size, 2, 1);
      return sub <= 2 ? put(out, size, v_.conf_date_time_[sub - 1], 4) : sdo_abort::kNoSubindex;
    case 0x1C14:
      return sub == 0 ? put(out, size, v_.lof_tolerance_ns_, 4) : sdo_abort::kNoSubindex;
    case 0x1F98:
      switch (sub) {
        case 0:
          return put(out, size, 9, 1);
        case 1:
          return put(out, size, v_.isochr_tx_max_payload_, 2);
        case 2:
          return put(out, size, v_.isochr_rx_max_payload_, 2);
        case 3:
          return put(out, size, v_.pres_max_latency_ns_, 4);
        case 4:
          return put(out, size, v_.preq_act_payload_, 2);
        case 5:
          return put(out, size, v_.pres_act_payload_, 2);
        case 6:
          return put(out, size, v_.asnd_max_latency_ns_, 4);
        case 7:
          return put(out, size, v_.multipl_cycle_cnt_, 1);
        case 8:
          return put(out, size, v_.async_mtu_, 2);
        case 9:
          return put(out, size, v_.prescaler_, 2);
        default:
          return sdo_abort::kNoSubindex;
      }
    case 0x1400:
    case 0x1800: {
      const PdoComm& c = index == 0x1400 ? v_.rx_comm_ : v_.tx_comm_;
      if (sub == 0) return put(out, size, 2, 1);
      if (sub == 1) return put(out, size, c.node_id, 1);
      if (sub == 2) return put(out, size, c.mapping_version, 1);
      return sdo_abort::kNoSubindex;
    }
    case 0x1600:
    case 0x1A00: {
      const Mapping& m = index == 0x1600 ? v_.rx_map_ : v_.tx_map_;
      if (sub == 0) return put(out, size, m.count, 1);
      if (sub > kMaxMapped) return sdo_abort::kNoSubindex;
      return put(out, size, m.entries[sub - 1], 8);
    }
    case 0x1F22:
      if (sub == 0) return put(out, size, 254, 1);
      if (out.size() < v_.dcf_size_) return sdo_abort::kGeneral;
      std::memcpy(out.data(), v_.dcf_.data(), v_.dcf_size_);
      size = v_.dcf_size_;
      return 0;
    default:
      return sdo_abort::kNoObject;
  }
}

uint32_t CnObjectDictionary::write(uint16_t index, uint8_t sub,
                                   std::span<const uint8_t> data) noexcept {
  switch (index) {
    case 0x1006:
      return sub == 0 ? take(v_.cycle_len_us_, data) : sdo_abort::kNoSubindex;
    case 0x1010:
    case 0x1011: {
      if (sub == 0) return sdo_abort::kReadOnly;
      if (sub != 1) return sdo_abort::kNoSubindex;
      // Without the signature ("save" / "load") DS 301 answers "data cannot be transferred or
      // stored".
      uint32_t signature = 0;
      if (const uint32_t a = take(signature, data)) return a;
      if (index == 0x1010) {
        if (signature != kSignatureSave) return sdo_abort::kCannotStore;
        stored_ = v_;
        has_stored_ = true;
      } else {
        // Defaults again from the next reset on (the values in use stay until then).
        if (signature != kSignatureLoad) return sdo_abort::kCannotStore;
        has_stored_ = false;
      }
      return 0;
    }
    case 0x1C0B:
    case 0x1C0C:
    case 0x1C0D:
    case 0x1C0F: {
      LossCounter& c = loss_counter(index);
      if (sub == 0 || sub == 2) return sdo_abort::kReadOnly;
      if (sub == 1) return take(c.cumulative, data);
      if (sub == 3) return take(c.threshold, data);
      return sdo_abort::kNoSubindex;
    }
    case 0x1020:
      if (sub == 0) return sdo_abort::kReadOnly;
      return sub <= 2 ? take(v_.conf_date_time_[sub - 1], data) : sdo_abort::kNoSubindex;
    case 0x1C14:
      return sub == 0 ? take(v_.lof_tolerance_ns_, data) : sdo_abort::kNoSubindex;
    case 0x1F98:
      switch (sub) {
        case 0:
        case 1:
        case 2:
        case 3:
        case 6:
          return sdo_abort::kReadOnly;  // the device's own limits
        case 4:
        case 5: {
          uint16_t v = 0;
          if (const uint32_t a = take(v, data)) return a;
          const uint16_t limit = sub == 4 ? v_.isochr_rx_max_payload_ : v_.isochr_tx_max_payload_;
          if (v > limit) return sdo_abort::kOutOfRange;
          (sub == 4 ? v_.preq_act_payload_ : v_.pres_act_payload_) = v;
          return 0;
        }
        case 7:
          return take(v_.multipl_cycle_cnt_, data);
        case 8:
          return take(v_.async_mtu_, data);
        case 9:
          return take(v_.prescaler_, data);
        default:
          return sdo_abort::kNoSubindex;
      }
    case 0x1400:
    case 0x1800: {
      PdoComm& c = index == 0x1400 ? v_.rx_comm_ : v_.tx_comm_;
      if (sub == 0) return sdo_abort::kReadOnly;
      if (sub == 1) return take(c.node_id, data);
      if (sub == 2) return take(c.mapping_version, data);
      return sdo_abort::kNoSubindex;
    }
    case 0x1600:
    case 0x1A00: {
      Mapping& m = index == 0x1600 ? v_.rx_map_ : v_.tx_map_;
      if (sub == 0) {
        uint8_t count = 0;
        if (const uint32_t a = take(count, data)) return a;
        if (count > kMaxMapped) return sdo_abort::kOutOfRange;
        m.count = count;
        return 0;
      }
      if (sub > kMaxMapped) return sdo_abort::kNoSubindex;
      // Mapping written while enabled (sub 0 ≠ 0): DS 301 wants it disabled first.
      if (m.count != 0) return sdo_abort::kDeviceState;
      uint64_t v = 0;
      if (const uint32_t a = take(v, data)) return a;
      m.entries[sub - 1] = v;
      return 0;
    }
    case 0x1F22:
      if (sub == 0) return sdo_abort::kReadOnly;
      if (data.size() > kMaxStoredDcf) return sdo_abort::kOutOfRange;
      std::memcpy(v_.dcf_.data(), data.data(), data.size());
      v_.dcf_size_ = data.size();
      return 0;
    default:
      return sdo_abort::kNoObject;
  }
}

CnObjectDictionary::LossCounter& CnObjectDictionary::loss_counter(uint16_t index) noexcept {
  return index == 0x1C0B   ? v_.loss_of_soc
         : index == 0x1C0C ? v_.loss_of_soa
         : index == 0x1C0D ? v_.loss_of_preq
                           : v_.crc_error;
}

const CnObjectDictionary::LossCounter& CnObjectDictionary::loss_counter(
    uint16_t index) const noexcept {
  return const_cast<CnObjectDictionary*>(this)->loss_counter(index);
}

uint16_t CnObjectDictionary::pres_size(uint16_t fallback) const noexcept {
  if (v_.pres_act_payload_ != 0) return v_.pres_act_payload_;
  if (v_.tx_map_.count != 0) return std::max(fallback, v_.tx_map_.end_bytes());
  return fallback;
}

uint16_t CnObjectDictionary::preq_size(uint16_t fallback) const noexcept {
  if (v_.preq_act_payload_ != 0) return v_.preq_act_payload_;
  if (v_.rx_map_.count != 0) return std::max(fallback, v_.rx_map_.end_bytes());
  return fallback;
}

}  // namespace ds1928::sim
