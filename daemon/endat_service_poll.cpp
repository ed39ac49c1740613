#include <algorithm>

#include "endat_service_state.hpp"
#include "x20ds1928/module_image.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Polling the tunnel

void EnDatService::arm_poll() {
  if (!running_) return;
  poll_timer_.expires_after(poll_period_);
  poll_timer_.async_wait(
      [this, alive = std::weak_ptr<bool>(alive_)](const boost::system::error_code& ec) {
        if (ec || alive.expired()) return;
        poll();
        arm_poll();
      });
}

void EnDatService::poll() {
  const auto now = Clock::now();
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    if (!running_) return;
    poll_axis(i, now);
    dispatch(i, now);
  }
}

void EnDatService::poll_axis(std::size_t index, Clock::time_point now) {
  Axis& a = *axes_[index];
  while (auto event = work_.poll_tunnel(index)) {
    switch (event->kind) {
      case TunnelEvent::Kind::Received: {
        if (!a.in_flight || !a.in_flight->submitted) {
          if (a.awaiting_late_reply) {
            // The reply to the command that timed out: it may now be forgotten.
            ++a.counters.late_replies;
            a.awaiting_late_reply = false;
          } else {
            ++a.counters.unexpected_replies;
          }
          break;
        }
        ++a.counters.replies;
        // The deadline runs from the first submission (transmit()).
        a.latency.record(std::chrono::duration_cast<std::chrono::nanoseconds>(
                             now - (a.in_flight->deadline - a.timeout))
                             .count());
        if (a.in_flight->job->cancelled) ++a.counters.discarded_replies;
        const endat::Request& request = a.in_flight->job->steps[a.in_flight->job->next];
        if (event->full_size > event->size) {
          finish_step(index, endat::Errc::oversized_reply, {});
          break;
        }
        auto reply = endat::decode_reply(
            request, std::span<const uint8_t>(event->bytes.data(), event->size));
        if (reply)
          finish_step(index, {}, *reply);
        else
          finish_step(index, reply.error(), {});
        break;
      }
      case TunnelEvent::Kind::Sent:
        if (a.in_flight && a.in_flight->submitted && event->tag == a.in_flight->tag)
          a.in_flight->sent = true;
        break;
      case TunnelEvent::Kind::SendFailed:
      case TunnelEvent::Kind::Rejected: {
        if (!a.in_flight || !a.in_flight->submitted || event->tag != a.in_flight->tag) break;
        const auto r = event->result;
        if (event->kind == TunnelEvent::Kind::SendFailed &&
            (r == flatstream::Errc::unconfirmed || r == flatstream::Errc::timeout)) {
          // The module may hold the command and answer it: keep waiting for the reply until
          // the command's deadline. It is still the only command in flight, so a reply that
          // comes is its reply.
          a.in_flight->maybe_delivered = true;
          break;
        }
        // Certainly not executed (not_synchronised, resend_limit, channel_reset, queue_full):
        // safe to send again.
        if (a.in_flight->resends < kMaxResends && now < a.in_flight->deadline) {
          ++a.in_flight->resends;
          ++a.counters.resends;
          transmit(index, now);
        } else {
          finish_step(index, EnDatServiceErrc::not_delivered, {});
        }
        break;
      }
    }
  }
  if (a.in_flight && now >= a.in_flight->deadline && a.in_flight->deadline != Clock::time_point{}) {
    ++a.counters.timeouts;
    const bool submitted = a.in_flight->submitted;
    if (submitted && !a.in_flight->sent && !a.in_flight->maybe_delivered) {
      // Still in the master's Flatstream queue: drop it so it cannot run later.
      TunnelRequest reset;
      reset.kind = TunnelRequest::Kind::ResetChannel;
      (void)work_.submit_tunnel(index, reset);
    }
    if (submitted) {
      a.awaiting_late_reply = true;
      a.quiet_until = now + a.timeout;
    }
    finish_step(index, EnDatServiceErrc::timeout, {});
  }
}

}  // namespace ds1928
