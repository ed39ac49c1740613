// BusDriver over POWERLINK: one POWERLINK cycle per exchange() on the cycle thread — SoC, PReq/PRes
// per isochronous CN (polling the link until each PRes timeout), SoA and the async frame — with
// the ManagingNode core deciding the contents. Register requests become SDO transfers.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "core/bus.hpp"
#include "core/spsc_queue.hpp"
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

class PowerlinkBus final : public BusDriver {
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
  [[nodiscard]] bool submit(const RegisterRequest& request) noexcept override;
  [[nodiscard]] bool poll(RegisterResult& out) noexcept override;

  // Normal thread: the latest status published by the cycle thread (at most one cycle old).
  [[nodiscard]] PowerlinkStatus status() const;
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
  void send(Result<std::size_t> len) noexcept;
  void drain(int64_t deadline_ns) noexcept;
  void publish_status() noexcept;

  MnConfig config_;
  std::unique_ptr<Link> owned_link_;
  Link& link_;
  ManagingNode mn_;
  std::vector<AxisMap> axis_map_;
  std::vector<int64_t> rx_time_;  // per axis: reception time of its PRes this cycle
  std::array<uint8_t, kMaxFrameSize> tx_{};
  std::array<uint8_t, kMaxFrameSize> rx_{};
  std::atomic<BusState> state_{BusState::Down};
  SpscQueue<RegisterRequest, 64> requests_;
  SpscQueue<RegisterResult, 64> results_;
  mutable std::mutex status_mutex_;
  PowerlinkStatus status_;
  Clock clock_;
};

}  // namespace ds1928::powerlink
