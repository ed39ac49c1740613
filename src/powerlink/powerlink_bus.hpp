// BusDriver over POWERLINK: one POWERLINK cycle per exchange() on the cycle thread — SoC, PReq/PRes
// per isochronous CN (polling the link until each PRes timeout), SoA and the async frame — with
// the ManagingNode core deciding the contents. Register requests become SDO transfers.
#pragma once

#include <array>
#include <atomic>
#include <bitset>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/bucket_histogram.hpp"
#include "core/bus.hpp"
#include "core/spsc_queue.hpp"
#include "core/triple_buffer.hpp"
#include "powerlink/cycle_occupancy.hpp"
#include "powerlink/link.hpp"
#include "powerlink/managing_node.hpp"

namespace ds1928::powerlink {

inline constexpr std::size_t kMaxStatusNodes = 32;

// Snapshot for `status` (normal thread).
struct PowerlinkStatus {
  NmtState mn_state = NmtState::kPreOperational1;
  MnCounters counters;
  bool link_up = false;
  std::array<CnStatus, kMaxStatusNodes> nodes{};
  std::size_t node_count = 0;
};

// Bytes one raw PReq write request carries (pl-preq-set).
inline constexpr std::size_t kMaxPreqWrite = 256;

// The last PRes payload of one configured CN, as the cycle thread last published it. Raw bytes:
// for a CN without X20DS1928 modules this is its whole process input.
struct PresSnapshot {
  uint8_t node = 0;
  bool received = false;   // a PRes has arrived since the start
  bool fresh = false;      // ... in the last published cycle
  bool ready = false;      // its RD flag: 0 = the CN's data is not ready (not taken as inputs)
  uint64_t cycle = 0;      // MN cycle count when it arrived
  int64_t rx_time_ns = 0;  // CLOCK_MONOTONIC reception time
  uint16_t size = 0;
  std::array<uint8_t, kMaxIsoPayload> payload{};
  [[nodiscard]] std::span<const uint8_t> bytes() const noexcept { return {payload.data(), size}; }
};

// Outcome of a raw PReq write request, with what the caller needs to word its error.
struct PreqWriteCheck {
  std::error_code error;   // MnError::kNodeNotConfigured, kPreqWriteTooLong, kPreqOutOfRange,
                           // kPreqRegionOwnedByModule, kQueueFull; empty: queued
  uint16_t preq_size = 0;  // the CN's PReq payload size the write was checked against
  ModuleMapping module{};  // kPreqRegionOwnedByModule: the module whose bytes it overlaps
};

// PRes latency per CN: PReq handed to the link → its PRes received (the link's receive stamp),
// bucket bounds in ns for the metrics endpoint. Written by the cycle thread.
inline constexpr std::array<int64_t, 12> kPresLatencyBoundsNs{
    10'000,  20'000,  50'000,  100'000,   150'000,   200'000,
    300'000, 500'000, 750'000, 1'000'000, 2'000'000, 5'000'000};
using PresLatencyHistogram = BucketHistogram<kPresLatencyBoundsNs>;

class PowerlinkBus final : public BusDriver, private RegisterTarget {
 public:
  // `config.axes` are the axes in the order exchange() receives them. The link outlives the bus.
  PowerlinkBus(const MnConfig& config, Link& link);
  PowerlinkBus(const MnConfig& config, std::unique_ptr<Link> link);

  [[nodiscard]] std::string_view name() const noexcept override { return "powerlink"; }
  [[nodiscard]] std::error_code start() override;
  void stop() noexcept override;
  ExchangeResult exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                          uint64_t cycle_index) noexcept override;
  [[nodiscard]] BusState state() const noexcept override {
    return state_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] const MnConfig& config() const noexcept { return config_; }

  // Normal thread (one thread: status(), pres_snapshot() and set_preq() share the reading side
  // of the snapshot): the latest status published by the cycle thread (at most one cycle old).
  [[nodiscard]] PowerlinkStatus status() const;
  // Normal thread: the last PRes of a configured CN; false when `node` is not configured.
  [[nodiscard]] bool pres_snapshot(uint8_t node, PresSnapshot& out) const;
  // Normal thread (the single producer): set `bytes` at `offset` of the PReq payload of `node`.
  // The cycle thread applies it from its next cycle on and keeps it for all following cycles
  // (also across a re-boot of the CN). Checked here against the CN's PReq size as last published
  // (0 until the CN is identified) and against the module regions, which belong to the axes.
  [[nodiscard]] PreqWriteCheck set_preq(uint8_t node, uint16_t offset,
                                        std::span<const uint8_t> bytes);
  // Normal thread: a configured CN's process image as the cycle thread last bound it (at start,
  // and when its own PDO mapping was read at boot): where it comes from, the module layout, and
  // the mapped objects (index, sub-index, bit offset, bit length) it was bound from. False when
  // `node` is not configured.
  struct MappedImage {
    uint8_t node = 0;
    ImageSource source = ImageSource::kPacked;
    std::error_code error;
    std::array<char, 120> refusal{};
    NodeImageLayout layout{};
    std::array<PdoMapEntry, kMaxPdoMapEntries> tpdo{};
    std::array<PdoMapEntry, kMaxPdoMapEntries> rpdo{};
    uint16_t tpdo_count = 0;
    uint16_t rpdo_count = 0;
  };
  [[nodiscard]] bool mapped_image(uint8_t node, MappedImage& out) const;
  // Any thread: the PRes latency of a configured CN; nullptr when `node` is not configured.
  [[nodiscard]] const PresLatencyHistogram* pres_latency(uint8_t node) const noexcept;
  // Measured cycle occupancy after the SoC left: the end of the isochronous phase (last PRes
  // received or timed out) and of the asynchronous phase (the exchange's end). Any thread.
  [[nodiscard]] const OccupancyHistogram& isochronous_end() const noexcept { return iso_end_; }
  [[nodiscard]] const OccupancyHistogram& async_end() const noexcept { return async_end_; }
  // Cycle thread (or tests driving exchange() themselves).
  [[nodiscard]] const ManagingNode& managing_node() const noexcept { return mn_; }

  // Clock (CLOCK_MONOTONIC) for the SoC send instant, receive deadlines and the cycle-time check;
  // tests may replace it.
  using Clock = int64_t (*)() noexcept;
  void set_clock(Clock clock) noexcept { clock_ = clock; }

 private:
  struct AxisMap {
    uint8_t node = 0;
    ModuleMapping mapping{};
    bool valid = false;
  };
  // Per configured CN. `node` is fixed at construction (read by both threads); the rest is the
  // cycle thread's.
  struct NodeRaw {
    uint8_t node = 0;
    std::array<uint8_t, kMaxIsoPayload> preq_set{};  // raw PReq bytes set through set_preq()
    std::bitset<kMaxIsoPayload> preq_mask;           // which of them were set
    uint16_t set_lo = 0, set_hi = 0;                 // [lo, hi) spans every set byte
    bool pres_fresh = false;
    bool pres_received = false;
    bool pres_ready = false;  // RD of the last PRes
    bool outputs_ok = true;   // every axis of the node wrote its outputs this cycle
    uint64_t pres_cycle = 0;
    int64_t pres_rx_ns = 0;
  };
  struct PreqWrite {
    uint8_t node = 0;
    uint16_t offset = 0;
    uint16_t length = 0;
    std::array<uint8_t, kMaxPreqWrite> bytes{};
  };
  // A register request becomes an SDO transfer of the MN to the axis' CN; one the node's SDO
  // queue has no room for yet waits in the register path (in order).
  Offer offer(const RegisterRequest& request) noexcept override;
  [[nodiscard]] NodeRaw* raw(uint8_t node) noexcept;
  [[nodiscard]] const NodeRaw* raw(uint8_t node) const noexcept;
  void apply_preq_writes() noexcept;
  void send(Result<std::size_t> len) noexcept;
  void drain(int64_t deadline_ns) noexcept;
  void prc_slot(ExchangeResult& result, std::size_t n_axes) noexcept;
  void note_pres(uint8_t node, int64_t t, int64_t sent_ns, std::size_t n_axes) noexcept;
  void publish_status() noexcept;
  void sync_layouts() noexcept;  // axis_map_ from the MN's layouts

  MnConfig config_;
  std::unique_ptr<Link> owned_link_;
  Link& link_;
  ManagingNode mn_;
  std::vector<AxisMap> axis_map_;
  uint32_t layouts_version_ = 0;    // of the MN's layouts axis_map_ was taken from
  uint32_t foreign_mn_frames_ = 0;  // the MN's count at the last cycle's end
  bool foreign_mn_seen_ = false;    // the last cycle saw another MN's frames
  std::vector<int64_t> rx_time_;    // per axis: reception time of its PRes this cycle
  std::array<uint8_t, kMaxFrameSize> tx_{};
  std::array<uint8_t, kMaxFrameSize> rx_{};
  std::atomic<BusState> state_{BusState::Down};
  std::vector<NodeRaw> raw_;
  std::unique_ptr<PresLatencyHistogram[]> pres_latency_;  // per raw_ entry
  OccupancyHistogram iso_end_;
  OccupancyHistogram async_end_;
  int64_t iso_end_ns_ = 0;  // this cycle: the last PRes received or given up on
  SpscQueue<PreqWrite, 16> preq_writes_;
  // What the cycle thread publishes each cycle for the normal thread; `pres` per raw_ entry.
  struct Snapshot {
    PowerlinkStatus status;
    std::vector<PresSnapshot> pres;
  };
  mutable TripleBuffer<Snapshot> snapshot_;
  // Published when a layout changes (sync_layouts()); per configured CN, in raw_ order.
  mutable TripleBuffer<std::vector<MappedImage>> mapped_;
  Clock clock_;
};

}  // namespace ds1928::powerlink
