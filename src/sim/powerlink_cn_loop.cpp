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
    if (period == 0 || gap > 4 * period) {
      period = gap;
    } else {
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

bool PowerlinkCnLoop::run_once() noexcept {
  int64_t now = rt::now_ns();
  int64_t node_deadline = INT64_MAX;
  for (PowerlinkCn* n : nodes_) node_deadline = std::min(node_deadline, n->next_deadline_ns());

  const int64_t next_start = next_cycle_start(now);
  if (next_start != 0 && cycle_done_) {
    // Idle phase: this cycle's frames are handled; frames that still come (an ASnd from the MN
    // after its SoA) wait in the ring until the wake-up.
    const int64_t wake =
        std::min({next_start - options_.guard_ns, node_deadline, now + options_.idle_wait_ns});
    if (wake > now) (void)rt::sleep_until(wake);
    now = rt::now_ns();
  } else if (next_start == 0 && node_deadline > now) {
    // No rhythm known (MN silent or just starting): block until something comes.
    (void)wait_readable_(std::min(node_deadline, now + options_.idle_wait_ns));
    now = rt::now_ns();
  }
  cycle_done_ = false;

  // Busy phase: poll until this cycle's SoA went by (or a bounded window passed).
  const int64_t period = soc_.valid(now) ? soc_.period : soa_.valid(now) ? soa_.period : 0;
  const int64_t end = now + (period > 0 ? period + options_.guard_ns : options_.idle_wait_ns);
  bool ok = true;
  while (!cycle_done_ && now < end) {
    const pl::Received r = link_.receive(rx_, std::min(end, node_deadline));
    now = r.rx_time_ns != 0 ? r.rx_time_ns : rt::now_ns();
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
