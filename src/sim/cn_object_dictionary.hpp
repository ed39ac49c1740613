// The simulated CN's standard objects (EPSG DS 301): every row of powerlink/standard_objects.hpp
// a CN holds — identity, error register, cycle length, store/restore, configuration date/time,
// DLL loss/CRC counters, loss-of-SoC tolerance, cycle timing, PDO communication and mapping, the
// concise DCF (accepted and kept) — served by one generic read and write over the table and fixed
// storage. Objects the table does not give a CN are refused with 0x06020000, subindices with
// 0x06090011 (the caller's other objects first). The few rules a type and an access cannot say
// (store/restore signatures, the payload limits of 0x1F98/4,5, PDO mappings written while
// disabled) are named in write().
// Fixed storage, no allocation: the SDO server calls it from the CN's cycle loop.
// Pure: returns SDO abort codes (0 = done).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "powerlink/concise_dcf.hpp"
#include "powerlink/standard_objects.hpp"

namespace ds1928::sim {

class CnObjectDictionary {
 public:
  static constexpr std::size_t kMaxMapped = 32;       // PDO mapping entries per direction
  static constexpr std::size_t kMaxStoredDcf = 1024;  // bytes of the concise DCF kept

  CnObjectDictionary() noexcept;

  // False when `index` is none of these objects (the caller looks elsewhere).
  [[nodiscard]] static bool handles(uint16_t index) noexcept;
  [[nodiscard]] uint32_t read(uint16_t index, uint8_t subindex, std::span<uint8_t> out,
                              std::size_t& size) const noexcept;
  [[nodiscard]] uint32_t write(uint16_t index, uint8_t subindex,
                               std::span<const uint8_t> data) noexcept;

  // The device's own values (read-only over SDO): identity, error register.
  void set_identity(uint32_t device_type, uint32_t vendor_id, uint32_t product_code,
                    uint32_t revision_no, uint32_t serial_no) noexcept;
  void set_error_register(uint8_t bits) noexcept;
  // The device's own PDO mapping (0x1A00 TPDO, 0x1600 RPDO): in use from now on and what a reset
  // restores when nothing was stored. False (nothing set) with more than kMaxMapped entries.
  [[nodiscard]] bool set_own_mapping(uint16_t mapping_index,
                                     std::span<const powerlink::PdoMapEntry> entries) noexcept;

  // The payload sizes the objects define: cycle timing /5 (/4) when written, else the end of the
  // mapped objects of the TPDO (RPDO) mapping when mapped, else `fallback` (the modules' layout).
  [[nodiscard]] uint16_t pres_size(uint16_t fallback) const noexcept;
  [[nodiscard]] uint16_t preq_size(uint16_t fallback) const noexcept;
  // The entries of PDO mapping `mapping_index` (0x1600 RPDO, 0x1A00 TPDO), as many as its sub 0
  // says (at most out.size()); 0 = the mapping is disabled.
  [[nodiscard]] std::size_t mapping(uint16_t mapping_index,
                                    std::span<powerlink::PdoMapEntry> out) const noexcept;
  // The node whose frame an RPDO channel takes (PDO_RxCommParam_XXh NodeID_U8 of `comm_index`):
  // 0 the PReq, 240 the PResMN.
  [[nodiscard]] uint8_t rpdo_source(uint16_t comm_index) const noexcept;
  [[nodiscard]] uint32_t cycle_length_us() const noexcept;
  [[nodiscard]] uint8_t multiplexed_cycle_count() const noexcept;
  [[nodiscard]] uint32_t loss_of_frame_tolerance_ns() const noexcept;
  // CFM_VerifyConfiguration /1, /2: the IdentResponse's VerifyConfigurationDate/Time, which an MN
  // compares with the configuration it expects (CFM_ExpConfDateList/TimeList) to skip a download.
  [[nodiscard]] uint32_t configuration_date() const noexcept;
  [[nodiscard]] uint32_t configuration_time() const noexcept;
  // Power-up, NMTResetNode, NMTResetCommunication: the values stored by NMT_StoreParam
  // (non-volatile), else the defaults. NMTResetConfiguration keeps the values written: it is how
  // an MN makes a CN take the configuration it just downloaded.
  void reset_communication() noexcept;

  // Storage slots: one per CN row and sub-index (arrays up to kMaxMapped entries).
  static constexpr std::size_t kSlots = [] {
    std::size_t n = 0;
    for (const powerlink::StandardObject& o : powerlink::kStandardObjects)
      if (o.holder == powerlink::ObjHolder::kCn && o.type != powerlink::ObjType::kDomain) {
        const std::size_t entries = std::size_t{o.sub_last} - o.sub_first + 1;
        n += entries > kMaxMapped ? kMaxMapped : entries;
      }
    return n;
  }();

 private:
  // Every value an MN can write: the live set and the one NMT_StoreParam stored.
  struct Values {
    std::array<uint64_t, kSlots> slot{};
    std::array<uint8_t, kMaxStoredDcf> dcf{};
    std::size_t dcf_size = 0;
  };
  // The slot of index/subindex; nullptr with `abort` set when the CN has no such object.
  [[nodiscard]] const uint64_t* find(uint16_t index, uint8_t subindex,
                                     const powerlink::StandardObject*& row,
                                     uint32_t& abort) const noexcept;
  [[nodiscard]] uint64_t value(uint16_t index, uint8_t subindex) const noexcept;
  [[nodiscard]] uint16_t mapped_end_bytes(uint16_t mapping_index) const noexcept;
  void set(uint16_t index, uint8_t subindex, uint64_t v) noexcept;

  Values v_;
  Values factory_;  // the defaults a reset restores without stored values
  Values stored_;
  bool has_stored_ = false;
};

}  // namespace ds1928::sim
