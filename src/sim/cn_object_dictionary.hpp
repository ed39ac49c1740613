// The communication objects of the simulated CN that an MN's configuration manager writes
// (EPSG DS 301): 0x1006 cycle length, 0x1020 configuration date/time, 0x1C0B/0x1C0C/0x1C0D/
// 0x1C0F the CN's DLL loss/CRC counters, 0x1C14 loss-of-frame tolerance, 0x1F98 cycle timing,
// 0x1400/0x1800 PDO communication, 0x1600/0x1A00 PDO mapping, 0x1F22 concise DCF (accepted and
// kept), 0x1010 store ("save") and 0x1011 restore defaults ("load"). Objects it does not have
// are refused with 0x06020000, subindices with 0x06090011 (the caller's other objects first).
// Fixed storage, no allocation: the SDO server calls it from the CN's cycle loop.
// Pure: returns SDO abort codes (0 = done).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace ds1928::sim {

class CnObjectDictionary {
 public:
  static constexpr std::size_t kMaxMapped = 32;       // PDO mapping entries per direction
  static constexpr std::size_t kMaxStoredDcf = 1024;  // bytes of 0x1F22 kept

  // False when `index` is none of these objects (the caller looks elsewhere).
  [[nodiscard]] static bool handles(uint16_t index) noexcept;
  [[nodiscard]] uint32_t read(uint16_t index, uint8_t subindex, std::span<uint8_t> out,
                              std::size_t& size) const noexcept;
  [[nodiscard]] uint32_t write(uint16_t index, uint8_t subindex,
                               std::span<const uint8_t> data) noexcept;

  // The payload sizes the objects define: 0x1F98/5 (/4) when written, else the end of the
  // mapped objects of 0x1A00 (0x1600) when mapped, else `fallback` (the modules' layout).
  [[nodiscard]] uint16_t pres_size(uint16_t fallback) const noexcept;
  [[nodiscard]] uint16_t preq_size(uint16_t fallback) const noexcept;
  [[nodiscard]] uint32_t cycle_length_us() const noexcept { return v_.cycle_len_us_; }
  [[nodiscard]] uint8_t multiplexed_cycle_count() const noexcept { return v_.multipl_cycle_cnt_; }
  [[nodiscard]] uint32_t loss_of_frame_tolerance_ns() const noexcept {
    return v_.lof_tolerance_ns_;
  }
  // 0x1020/1, /2: the IdentResponse's VerifyConfigurationDate/Time, which an MN compares with
  // the configuration it expects (0x1F26/0x1F27) to skip a download.
  [[nodiscard]] uint32_t configuration_date() const noexcept { return v_.conf_date_time_[0]; }
  [[nodiscard]] uint32_t configuration_time() const noexcept { return v_.conf_date_time_[1]; }
  // Power-up, NMTResetNode, NMTResetCommunication: the values stored by 0x1010 (non-volatile),
  // else the defaults. NMTResetConfiguration keeps the values written: it is how an MN makes a
  // CN take the configuration it just downloaded.
  void reset_communication() noexcept { v_ = has_stored_ ? stored_ : Values{}; }

 private:
  struct Mapping {
    uint8_t count = 0;
    std::array<uint64_t, kMaxMapped> entries{};
    [[nodiscard]] uint16_t end_bytes() const noexcept;
  };
  // DLL_CN*_REC: sub 1 cumulative count, 2 threshold counter (read-only), 3 threshold.
  struct LossCounter {
    uint32_t cumulative = 0;
    uint32_t threshold_count = 0;
    uint32_t threshold = 15;
  };
  struct PdoComm {
    uint8_t node_id = 0;
    uint8_t mapping_version = 0;
  };

  // Every value an MN can write: the live set and the one 0x1010 stored.
  struct Values {
    uint32_t cycle_len_us_ = 0;
    std::array<uint32_t, 2> conf_date_time_{};  // 0x1020/1, /2
    uint32_t lof_tolerance_ns_ = 300'000;
    // 0x1F98 NMT_CycleTiming_REC, sub 1..9.
    uint16_t isochr_tx_max_payload_ = 1490;
    uint16_t isochr_rx_max_payload_ = 1490;
    uint32_t pres_max_latency_ns_ = 2000;
    uint16_t preq_act_payload_ = 0;  // 0 = not written
    uint16_t pres_act_payload_ = 0;
    uint32_t asnd_max_latency_ns_ = 2000;
    uint8_t multipl_cycle_cnt_ = 0;
    uint16_t async_mtu_ = 300;
    uint16_t prescaler_ = 2;
    PdoComm rx_comm_, tx_comm_;
    Mapping rx_map_, tx_map_;
    std::array<uint8_t, kMaxStoredDcf> dcf_{};
    std::size_t dcf_size_ = 0;
    LossCounter loss_of_soc, loss_of_soa, loss_of_preq,
        crc_error;  // 0x1C0B, 0x1C0C, 0x1C0D, 0x1C0F
  };
  [[nodiscard]] LossCounter& loss_counter(uint16_t index) noexcept;
  [[nodiscard]] const LossCounter& loss_counter(uint16_t index) const noexcept;

  Values v_;
  Values stored_;
  bool has_stored_ = false;
};

}  // namespace ds1928::sim
