// The virtual CAN bus: a TEST TRANSPORT standing in for a CAN network where the kernel has no
// CAN (unit tests, the simulator, fault injection). Two modes:
//  - timed (VirtualBusOptions::bitrate > 0, the default of the daemon and the simulator): a
//    frame occupies the bus for its real stuffed length at the bit rate (frame_wire_bits), one
//    frame at a time; frames waiting in several ports' TX queues go out by arbitration (lowest
//    identifier first, standard before extended with the same base); each port's queue is FIFO
//    (one controller TX buffer); receivers get a frame at its end of frame, stamped with it.
//    Not modelled: ACK and bit errors (no error frames from the wire), the bit-level collision of
//    two ports sending the same identifier (they go one after the other).
//  - instant (bitrate 0): a sent frame is on the bus at once, stamped with the send time.
// What it keeps from CAN in both modes is what the drivers depend on:
// a broadcast medium (every port sees every other port's frames, not its own), per-port
// identifier filters and error-frame subscription, RX time stamps, and the controller states
// with bus-off and restart behaving as the kernel reports them.
//
// Medium: one ring of frame slots, written by any port (ticket = fetch_add on the head), read by
// every port at its own pace (a reader lapped by the writers loses the overwritten frames and
// counts them as rx_kernel_drops, like SO_RXQ_OVFL). Slots are plain atomics, waiting is a futex
// on the publish counter, so the ring works the same in process memory
// (VirtualCanBus::create_local) and in POSIX shared memory between processes
// (VirtualCanBus::open_shared): ds1928d and `ds1928-sim canio` talk over it without AF_CAN. Shared
// memory was chosen over a Unix datagram socket per port because a broadcast needs no peer list,
// send is one slot write with no syscall unless a reader sleeps, and nothing on the send/receive
// path allocates.
//
// Fault injection is per port and thread-safe (atomics; error frames through a small SPSC queue
// with one injecting thread): random loss with a seeded RNG, "drop the next k frames with id X",
// delivery delayed by receive polls or by time, injected error frames, bus-off with the kernel's
// recovery (restart-ms on the bus clock, or restart()).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "can/can_error_frame.hpp"
#include "can/can_port.hpp"

namespace ds1928::canio {

struct VirtualBusOptions {
  // Frame slots in the ring (power of two). A reader falling this many frames behind loses frames.
  uint32_t ring_frames = 1024;
  // Clock for RX stamps, delays and bus-off restart (CLOCK_MONOTONIC ns). Empty: the real
  // CLOCK_MONOTONIC. Tests pass a fake clock; receive() deadlines are read on the same clock.
  std::function<int64_t()> clock;
  // Bit rate of the timed bus (bit/s); 0: instant bus (no bit timing, no arbitration). A shared
  // bus keeps the creator's: opening it at another bit rate is an error naming both.
  uint32_t bitrate = 0;
  // Virtual time: called instead of sleeping when receive() would wait for the bus clock to reach
  // `until_ns` (the next end of frame, the next frame's start, a delayed frame, or the caller's
  // deadline). The fake clock's owner moves its clock (up to until_ns) and may run peers there;
  // receive() goes on from the new time and returns empty if the clock did not move. Empty: sleep.
  std::function<void(int64_t until_ns)> wait_until = {};
};

// The options the daemon and the simulator open their shared bus with: timed at `bitrate`, or
// instant (bitrate 0) when the environment has DS1928_VIRTUAL_BUS_INSTANT=1 — for a test that
// needs the old instant delivery across processes. Both sides must agree (checked on open).
[[nodiscard]] VirtualBusOptions virtual_bus_options(uint32_t bitrate);

// Bus time of frames on a timed bus: totals since the bus was created.
struct WireTotals {
  uint64_t frames = 0;      // frames that went on the wire
  int64_t busy_ns = 0;      // their bus time (stuffed bits, intermission included)
  int64_t bus_free_ns = 0;  // bus clock at which the last frame's intermission ends
};

// Bus load over a window of the bus clock.
struct BusLoad {
  int64_t from_ns = 0, to_ns = 0;
  int64_t busy_ns = 0;  // bus time of frames inside the window
  uint64_t frames = 0;  // frames with bus time inside the window
  double load = 0.0;    // busy_ns / (to_ns - from_ns)
};

struct VirtualPortOptions {
  std::string name = "vcan";  // for messages and query_interface()
  // Reported by query_interface() on an instant bus; a timed bus reports its own bit rate.
  uint32_t bitrate = 500'000;
  // After an injected bus-off, the port restarts by itself this long after (bus clock), as the
  // kernel does with `restart-ms`; 0: stays bus-off until restart().
  uint32_t restart_ms = 100;
};

// Which way a fault applies: frames this port receives, or frames it sends (then no port sees
// them).
enum class FaultDirection : uint8_t { Rx = 0, Tx = 1 };

struct FaultCounters {
  uint64_t rx_lost = 0;         // dropped on receive by random loss or drop_next
  uint64_t tx_lost = 0;         // dropped on send by random loss or drop_next (send said Sent)
  uint64_t delayed = 0;         // frames that went through the delay queue
  uint64_t delay_overflow = 0;  // delay queue full: frame dropped
  uint64_t errors_injected = 0;
  uint64_t sends_failed = 0;    // by fail_next_sends
  uint64_t missed_off_bus = 0;  // frames on the bus while this port was bus-off or down
};

class VirtualCanBus;

class VirtualCanPort final : public CanPort {
 public:
  ~VirtualCanPort() override;
  VirtualCanPort(const VirtualCanPort&) = delete;
  VirtualCanPort& operator=(const VirtualCanPort&) = delete;

  // CanPort
  SendResult send(const CanFrame& frame) noexcept override;
  ReceiveResult receive(std::span<CanFrame> frames, int64_t deadline_ns) noexcept override;
  [[nodiscard]] CanState state() const noexcept override;
  [[nodiscard]] CanPortCounters counters() const noexcept override;
  [[nodiscard]] std::error_code set_filters(std::span<const CanIdFilter> ids) noexcept override;
  [[nodiscard]] std::error_code set_error_mask(uint32_t classes) noexcept override;
  [[nodiscard]] Result<CanInterfaceInfo> query_interface() noexcept override;
  [[nodiscard]] std::string_view name() const noexcept override { return options_.name; }

  // ---- fault injection (any thread) ---------------------------------------------------------

  // Random loss: each frame is dropped with `probability` (0..1), from a xorshift RNG seeded
  // with `seed` (reproducible runs).
  void set_loss(FaultDirection dir, double probability, uint64_t seed) noexcept;
  // Drops the next `count` frames with identifier `id` (standard or extended alike).
  void drop_next(FaultDirection dir, uint32_t id, uint32_t count) noexcept;
  // Received frames are handed out only after `polls` further receive() calls (0: off).
  void set_delay_polls(uint32_t polls) noexcept;
  // Received frames are handed out only `ns` after they were sent (bus clock; 0: off). Their
  // RX stamp is the delivery time, as a late frame on a real bus would be stamped.
  void set_delay_ns(int64_t ns) noexcept;
  // Delivers `event` to this port as an error frame (if its class is subscribed) and applies its
  // state change. False when the injection queue (16) is full. One injecting thread at a time.
  bool inject_error(const CanErrorEvent& event) noexcept;
  // Every OTHER port on the bus (in any process) takes `event` as if its own controller had
  // reported it: state change, and the error frame if subscribed. The way a simulator process
  // makes the daemon's port go bus-off or error-passive. Any thread.
  bool broadcast_error(const CanErrorEvent& event) noexcept;
  // The controller goes bus-off at once: state BusOff, send() answers BusOff, a bus-off error
  // frame for the next receive(); after restart_ms on the bus clock (if not 0) the port restarts
  // by itself: restarted error frame, error-active. Always true.
  bool inject_bus_off() noexcept;
  // Manual restart of a bus-off controller (`ip link set canX type can restart`).
  void restart() noexcept;
  // Administrative up/down: down → send() InterfaceDown, receive() kInterfaceDown.
  void set_up(bool up) noexcept;
  // The next `count` send() calls fail with `status` (QueueFull: as ENOBUFS, InterfaceDown: as
  // ENETDOWN, Failed: as EIO) without reaching the bus.
  void fail_next_sends(uint32_t count, SendStatus status = SendStatus::QueueFull) noexcept;

  [[nodiscard]] FaultCounters fault_counters() const noexcept;

 private:
  friend class VirtualCanBus;
  struct Impl;
  VirtualCanPort(std::shared_ptr<VirtualCanBus> bus, uint16_t index, VirtualPortOptions options);

  std::shared_ptr<VirtualCanBus> bus_;
  VirtualPortOptions options_;
  std::unique_ptr<Impl> impl_;  // allocated once at open; the hot path only uses it
  int tx_queue_ = -1;           // timed bus: this port's TX queue in the ring
};

class VirtualCanBus : public std::enable_shared_from_this<VirtualCanBus> {
 public:
  // A bus in this process' memory.
  [[nodiscard]] static std::shared_ptr<VirtualCanBus> create_local(VirtualBusOptions options = {});
  // A bus in POSIX shared memory "/ds1928-vcan.<name>", created by whichever process opens it
  // first (same ring size required: kVirtualBusMismatch otherwise; same bit rate: otherwise an
  // error whose message names both). With unlink_on_close the
  // name is removed when this object goes (the mapping stays valid in other processes).
  [[nodiscard]] static Result<std::shared_ptr<VirtualCanBus>> open_shared(
      std::string_view name, VirtualBusOptions options = {}, bool unlink_on_close = false);
  // Removes the shared-memory name of a bus (leftovers of a crashed run).
  static std::error_code remove_shared(std::string_view name) noexcept;
  // The text for an open_shared() error: its message, and for a bus another user left behind
  // (EACCES: a stopped run's bus stays in /dev/shm, mode 0600) its file, owner and the command
  // that removes it.
  [[nodiscard]] static std::string open_error_text(std::string_view name, std::error_code ec);

  ~VirtualCanBus();
  VirtualCanBus(const VirtualCanBus&) = delete;
  VirtualCanBus& operator=(const VirtualCanBus&) = delete;

  // A new port on this bus; it sees frames sent from now on (by any other port). A timed bus
  // holds at most 32 ports' TX queues at once (all processes): beyond, ENOBUFS.
  [[nodiscard]] Result<std::unique_ptr<VirtualCanPort>> open_port(VirtualPortOptions options = {});

  [[nodiscard]] int64_t now_ns() const noexcept;

  // ---- timed bus (figures for tests and benches; not for the cycle thread) --------------------
  [[nodiscard]] uint32_t bitrate() const noexcept;  // 0: instant bus
  [[nodiscard]] bool timed() const noexcept { return bitrate() != 0; }
  // Bus time of this frame at the bus' bit rate (its stuffed bits, intermission included).
  [[nodiscard]] int64_t wire_time_ns(const CanFrame& frame) const noexcept;
  // Both bring the bus timeline up to now_ns() first (frames whose turn came go on the wire).
  [[nodiscard]] WireTotals wire_totals() noexcept;
  // Over the frames still in the ring (the last ring_frames).
  [[nodiscard]] BusLoad load(int64_t from_ns, int64_t to_ns) noexcept;

  struct Ring;  // shared layout (virtual_bus.cpp)

 private:
  VirtualCanBus() = default;
  friend class VirtualCanPort;

  VirtualBusOptions options_;
  Ring* ring_ = nullptr;
  std::size_t mapped_bytes_ = 0;
  bool shared_ = false;
  std::string shm_name_;
  bool unlink_on_close_ = false;
};

}  // namespace ds1928::canio
