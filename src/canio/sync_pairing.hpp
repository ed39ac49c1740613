// Which input objects of one module make the sample of one SYNC (pure: no I/O, no clock, no
// allocation; one instance per axis, driven by the cycle thread).
//
// The master sends SYNC n, then waits until the response window ends. Every object that arrives
// is put in one of three places by its RX stamp (end of frame on the timed bus, the kernel's stamp
// on SocketCAN):
//   before  — stamped before SYNC n was handed to the bus (or drained before it was sent):
//             an answer to an earlier SYNC, late;
//   window  — stamped between the SYNC's send time and the deadline: a candidate for sample n;
//   after   — stamped past the deadline: late.
// The stamp alone cannot tell every late object: a slow bus controller may send object 2 of
// SYNC n−1 after SYNC n went out, so it lands in window n. What the wire and the node guarantee
// decides:
//   W1  a node answers object 1 before object 2 for the same SYNC (it queues them in that order;
//       the lower identifier of object 1 also wins arbitration), so object 2 of SYNC n always
//       follows object 1 of SYNC n;
//   W2  (ASSUMPTION, the bus controller) once a node has queued its answers to SYNC n it sends
//       no object of an earlier SYNC: a FIFO transmitter has sent them before, a controller with
//       one mailbox per identifier has overwritten them (it refills both mailboxes within far
//       less than one frame time, so object 1 of SYNC n cannot leave before object 2's mailbox
//       holds SYNC n's data);
//   W3  (ASSUMPTION) an object arrives before the deadline of the next SYNC or never.
// Hence for sample n:
//   object 1 = the object 1 in the window — exactly one; if the previous window had none (it may
//              be late, W3), exactly two and the second is taken (W2: the older one first);
//   object 2 = the one object 2 that follows that object 1 (W1 + W2: it answers SYNC n). An
//              object 2 before it answers an earlier SYNC: late, counted, never used.
// Anything else — a missing object, two objects 2 after object 1, a lone object 1 that may be
// the previous SYNC's — gives no sample: the cycle is stale and counted, never glued from two
// SYNCs.
#pragma once

#include <cstdint>

#include "canio/object_codec.hpp"

namespace ds1928::canio {

enum class PairingVerdict : uint8_t {
  Whole = 0,  // a sample of this SYNC: both objects, unambiguous
  Missing,    // neither object in the window
  Half,       // one object (or object 2 only before object 1): no sample
  Ambiguous,  // objects there, but which SYNC they answer is not certain: no sample
};

class SyncPairing {
 public:
  // Start of cycle n: objects that arrived since the last deadline (before the SYNC) are late.
  void late_before(ObjectKind kind) noexcept;
  // The window opens (SYNC n sent).
  void open() noexcept;
  // An object stamped inside the window.
  void in_window(ObjectKind kind, const CanObject& bytes, int64_t rx_ns) noexcept;
  // An object stamped after the deadline (late; it settles what was owed).
  void late_after(ObjectKind kind) noexcept;
  // An object that arrived but cannot be used (wrong length): it answered, so nothing is owed.
  void seen(ObjectKind kind) noexcept { late_after(kind); }
  // The window closes: the verdict, and the objects when Whole. `sync_sent` false: no SYNC went
  // out this cycle, so no answer to it can be owed.
  [[nodiscard]] PairingVerdict close(bool sync_sent = true) noexcept;

  // The window holds what sample n needs: the caller may stop waiting (objects after that are
  // late and settle nothing this sample depends on).
  [[nodiscard]] bool ready() const noexcept {
    return n1_ >= 1u + (owed1_at_open_ && owed1_ ? 1u : 0u) && n2_after_ >= 1;
  }
  [[nodiscard]] const CanObject& position() const noexcept { return position_; }
  [[nodiscard]] const CanObject& status() const noexcept { return status_; }
  [[nodiscard]] int64_t position_rx_ns() const noexcept { return position_rx_ns_; }
  [[nodiscard]] bool owed_position() const noexcept { return owed1_; }
  // Objects 2 the last window saw before its object 1 (answers to an earlier SYNC).
  [[nodiscard]] uint8_t late_in_window() const noexcept { return n2_before_; }
  // The last close() saw more objects than one SYNC (plus what was owed) can explain.
  [[nodiscard]] bool surplus() const noexcept { return surplus_; }
  // Forget what is owed (the node was silent for longer than A3's bound, or restarted).
  void reset() noexcept { *this = SyncPairing{}; }

 private:
  bool owed1_ = false;     // an object 1 of an earlier SYNC may still arrive in this window
  uint8_t n1_ = 0;         // objects 1 in the window
  uint8_t n2_ = 0;         // objects 2 in the window (all)
  uint8_t n2_after_ = 0;   // objects 2 after the last object 1
  uint8_t n2_before_ = 0;  // objects 2 in the window before the last object 1
  bool owed1_at_open_ = false;
  bool surplus_ = false;
  uint8_t n1_after_ = 0;  // stamped after the deadline (for what is owed next)
  CanObject position_{};
  CanObject status_{};
  int64_t position_rx_ns_ = 0;
};

}  // namespace ds1928::canio
