// The work of one cycle (DESIGN.md "One cycle", steps 2–5): exchange with the bus, decode each
// axis, run its Flatstream channel, publish to shared memory. Runs on the cycle thread; the
// normal thread talks to it only through the lock-free queues and atomics below.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "config/config.hpp"
#include "config/config_loader.hpp"
#include "core/axis_sample.hpp"
#include "core/bus.hpp"
#include "core/cycle_engine.hpp"
#include "core/spsc_queue.hpp"
#include "shm/publisher.hpp"

namespace ds1928 {

// A request from the normal thread for the cycle thread.
struct AxisCommand {
  enum class Kind : uint8_t { AckErrors };
  Kind kind = Kind::AckErrors;
  uint16_t axis = 0;
  uint8_t bits = 0;
};

// Per-axis figures the normal thread reads for `status` (single writer: the cycle thread).
struct AxisCounters {
  std::atomic<uint64_t> fresh_cycles{0};
  std::atomic<uint64_t> stale_cycles{0};
  std::atomic<uint64_t> new_positions{0};
  std::atomic<uint64_t> format_violations{0};  // fraction with low 3 bits set
  std::atomic<uint8_t> error_info{0};
  std::atomic<uint32_t> endat_error{0};    // written by the normal thread from acyclic reads
  std::atomic<uint32_t> endat_warning{0};  // idem
};

class CycleWork final : public CycleTask {
 public:
  static constexpr uint32_t kAckHoldCycles = 8;  // AckErrorInfo stays set this many cycles

  CycleWork(const DaemonConfig& config, BusDriver& bus, shm::Publisher& publisher);

  void run_cycle(const CycleContext& ctx) noexcept override;

  // Normal thread. False when the queue is full (the caller reports "busy").
  [[nodiscard]] bool post(const AxisCommand& command) noexcept { return commands_.try_push(command); }

  [[nodiscard]] std::size_t axis_count() const noexcept { return io_.size(); }
  [[nodiscard]] AxisCounters& counters(std::size_t axis) noexcept { return counters_[axis]; }
  [[nodiscard]] uint64_t exchanges() const noexcept { return exchanges_.load(std::memory_order_relaxed); }
  [[nodiscard]] uint64_t data_exchanges() const noexcept {
    return data_exchanges_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] uint64_t frames_lost() const noexcept { return frames_lost_.load(std::memory_order_relaxed); }
  [[nodiscard]] bool bus_up() const noexcept { return bus_up_.load(std::memory_order_relaxed); }

 private:
  BusDriver& bus_;
  shm::Publisher& publisher_;
  // Sized once at construction; never resized on the cycle thread.
  std::vector<AxisIo> io_;
  std::vector<AxisDecodeParams> params_;
  std::vector<AxisDecodeState> decode_state_;
  std::vector<shm::AxisStatus> status_;
  std::vector<uint8_t> ack_bits_;
  std::vector<uint32_t> ack_hold_;
  std::unique_ptr<AxisCounters[]> counters_;
  SpscQueue<AxisCommand, 64> commands_;
  std::atomic<uint64_t> exchanges_{0};
  std::atomic<uint64_t> data_exchanges_{0};
  std::atomic<uint64_t> frames_lost_{0};
  std::atomic<bool> bus_up_{false};
};

}  // namespace ds1928
