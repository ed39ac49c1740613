// PowerlinkCnLoop: drives simulated CNs from one raw link (see powerlink_cn.hpp).
#include <algorithm>
#include <cerrno>
#include <climits>

#include "core/clock.hpp"
#include "sim/powerlink_cn.hpp"

namespace ds1928::sim {

namespace pl = ds1928::powerlink;

// ---- Loop -----------------------------------------------------------------------------------

PowerlinkCnLoop::PowerlinkCnLoop(pl::Link& link, std::function<bool(int64_t)> wait_readable,
                                 std::span<PowerlinkCn* const> nodes, Options options)
    : link_(link),
      wait_readable_(std::move(wait_readable)),
      nodes_(nodes.begin(), nodes.end()),
      options_(options) {}

void PowerlinkCnLoop::Rhythm::note(int64_t t) noexcept {
  if (last != 0) {
    const int64_t gap = t - last;
    if (period == 0) {
      period = gap;
    } else if (gap > 4 * period) {
      if (++pauses >= 2) {
        period = gap;
        pauses = 0;
      }
    } else {
      pauses = 0;
      period += (gap - period) / 8;
    }
  }
  last = t;
}

int64_t PowerlinkCnLoop::next_cycle_start(int64_t now) const noexcept {
  // Only full cycles have a start to sleep toward: an MN's reduced cycle (PRE_OPERATIONAL_1,
  // SoA only) need not be periodic — openPOWERLINK's sends its next SoA as soon as the previous
  // slot is over — and an IdentRequest or StatusRequest that waited in the ring until a planned
  // wake-up would be answered after the MN's slot timeout. Without a SoC rhythm the loop blocks
  // until a frame arrives.
  if (soc_.valid(now)) return soc_.last + soc_.period;
  return 0;
}

void PowerlinkCnLoop::check_own_stall(int64_t due, int64_t now) noexcept {
  const int64_t late = now - due;
  if (late < options_.own_stall_min_ns || !options_.run_queue_wait_ns) return;
  // The part the kernel counted as waiting for a CPU is this machine's scheduling (a task of
  // higher priority ran): silence the simulator would have seen had it run, so it still counts.
  const int64_t waited = options_.run_queue_wait_ns();
  if (waited < 0) return;  // the kernel's count unreadable: the silence counts
  const int64_t host = late - std::max<int64_t>(0, waited - run_queue_wait_mark_);
  run_queue_wait_mark_ = waited;
  if (host < options_.own_stall_min_ns) return;
  for (PowerlinkCn* n : nodes_) n->note_own_stall(now - host, now);
}

bool PowerlinkCnLoop::run_once() noexcept {
  int64_t now = rt::now_ns();
  // The run-queue wait from here on: a stall found in this pass is compared with it.
  if (options_.run_queue_wait_ns) run_queue_wait_mark_ = options_.run_queue_wait_ns();
  int64_t node_deadline = INT64_MAX;
  for (PowerlinkCn* n : nodes_) node_deadline = std::min(node_deadline, n->next_deadline_ns());

  const int64_t next_start = next_cycle_start(now);
  if (next_start != 0 && cycle_done_) {
    // Idle phase: this cycle's frames are handled; frames that still come (an ASnd from the MN
    // after its SoA) wait in the ring until the wake-up.
    const int64_t wake =
        std::min({next_start - options_.guard_ns, node_deadline, now + options_.idle_wait_ns});
    const bool sleeps = wake > now;
    if (sleeps) (void)rt::sleep_until(wake);
    now = rt::now_ns();
    if (sleeps) check_own_stall(wake, now);
  } else if (next_start == 0 && node_deadline > now) {
    // No rhythm known (MN silent or just starting): block until something comes. (A frame
    // that ends the wait and is then read late: the receive below judges it by its stamp.)
    const int64_t until = std::min(node_deadline, now + options_.idle_wait_ns);
    const bool readable = wait_readable_(until);
    now = rt::now_ns();
    if (!readable) check_own_stall(until, now);
  }
  cycle_done_ = false;

  // Busy phase: poll until this cycle's SoA went by (or a bounded window passed).
  const int64_t period = soc_.valid(now) ? soc_.period : soa_.valid(now) ? soa_.period : 0;
  const int64_t end = now + (period > 0 ? period + options_.guard_ns : options_.idle_wait_ns);
  bool ok = true;
  while (!cycle_done_ && now < end) {
    const int64_t deadline = std::min(end, node_deadline);
    const int64_t called = rt::now_ns();
    const pl::Received r = link_.receive(rx_, deadline);
    const int64_t back = rt::now_ns();
    // Back by the deadline, or — a frame — as soon as it came (its kernel stamp) or the call
    // began. Only the waits are judged: the frames' handling may write a log line, and a thread
    // blocked in its own write is not one its host stopped.
    const int64_t due = r.rx_time_ns != 0 ? std::max(called, r.rx_time_ns)
                        : r.length != 0   ? back  // no stamp: nothing to judge by
                                          : std::max(called, deadline);
    check_own_stall(due, back);
    now = r.rx_time_ns != 0 ? r.rx_time_ns : back;
    if (r.error && r.length == 0) {
      ok = false;
      break;
    }
    if (r.length > 14) {
      const std::span<const uint8_t> frame(rx_.data(), r.length);
      // The node a SoA invites answers after every other node saw the SoA, as on the wire: the
      // others time a SyncResponse from the end of its SyncRequest (PollResponse Chaining).
      const bool soa =
          r.length > 21 && rx_[12] == 0x88 && rx_[13] == 0xAB && (rx_[14] & 0x7F) == 0x05;
      const uint8_t invited = soa ? rx_[21] : 0;
      PowerlinkCn* last = nullptr;
      for (PowerlinkCn* n : nodes_) {
        if (invited != 0 && n->node_id() == invited) {
          last = n;
          continue;
        }
        n->receive(frame, now);
      }
      if (last != nullptr) last->receive(frame, now);
      if (rx_[12] == 0x88 && rx_[13] == 0xAB) {
        const uint8_t type = rx_[14] & 0x7F;
        if (type == 0x01) soc_.note(now);
        if (type == 0x05) {
          soa_.note(now);
          cycle_done_ = true;  // after the SoA only the invited ASnd follows
        }
      }
    }
    node_deadline = INT64_MAX;
    for (PowerlinkCn* n : nodes_) {
      if (n->next_deadline_ns() <= now) n->tick(now);
      node_deadline = std::min(node_deadline, n->next_deadline_ns());
    }
  }
  for (PowerlinkCn* n : nodes_) n->tick(now);
  return ok;
}

}  // namespace ds1928::sim
