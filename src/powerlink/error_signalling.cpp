#include "powerlink/error_signalling.hpp"

#include <algorithm>
#include <cstdio>

namespace ds1928::powerlink {

std::string describe(const ErrorEntry& e) {
  const uint16_t profile = e.type & entry_type::kProfileMask;
  const char* prof = profile == entry_type::kProfilePowerlink ? "POWERLINK"
                     : profile == entry_type::kProfileVendor  ? "vendor"
                                                              : "device profile";
  const uint16_t mode = e.type & entry_type::kModeMask;
  const char* m = mode == entry_type::kModeActive     ? "active"
                  : mode == entry_type::kModeCleared  ? "cleared"
                  : mode == entry_type::kModeOccurred ? "occurred"
                                                      : "no mode";
  const char* kind = (e.type & entry_type::kStatus) != 0      ? ", status"
                     : (e.type & entry_type::kEmergency) != 0 ? ", emergency"
                                                              : "";
  // NetTime: seconds in the low word, nanoseconds in the high word.
  const auto seconds = static_cast<uint32_t>(e.timestamp);
  const auto nanoseconds = static_cast<uint32_t>(e.timestamp >> 32);
  std::array<char, 160> buf{};
  std::snprintf(buf.data(), buf.size(),
                "0x%04X (%s, %s%s) at %u.%09u s, info %02X %02X %02X %02X %02X %02X %02X %02X",
                e.code, prof, m, kind, seconds, nanoseconds, e.additional[0], e.additional[1],
                e.additional[2], e.additional[3], e.additional[4], e.additional[5], e.additional[6],
                e.additional[7]);
  return buf.data();
}

// ---- CN role ----------------------------------------------------------------------------------

void CnErrorSignalling::reset() noexcept {
  *this = CnErrorSignalling{};
}

void CnErrorSignalling::on_status_request(bool er, bool ea) noexcept {
  if (er != last_er_) {
    last_er_ = er;
    // Both edges restart the toggling: EN and the MN's EA both start from 0. What was sent is
    // sent again (the MN may have lost it with its reset).
    en_ = false;
    ea_ = false;
    sent_ = 0;
    ec_ = er;
    // Initialised (ER back to 0): entries still queued are signalled at once.
    if (!er && count_ > 0) en_ = true;
    return;
  }
  acknowledge(ea);
}

void CnErrorSignalling::on_preq(bool ea) noexcept {
  acknowledge(ea);
}

void CnErrorSignalling::acknowledge(bool ea) noexcept {
  ea_ = ea;
  if (last_er_ || ea_ != en_ || sent_ == 0) return;
  // The MN fetched what was sent and acknowledged the toggle: those entries are delivered.
  std::move(queue_.begin() + static_cast<std::ptrdiff_t>(sent_),
            queue_.begin() + static_cast<std::ptrdiff_t>(count_), queue_.begin());
  count_ -= sent_;
  sent_ = 0;
  // Entries queued since the StatusResponse went out: a new toggle.
  if (count_ > 0) en_ = !en_;
}

void CnErrorSignalling::queue(ErrorEntry e) noexcept {
  e.type |= entry_type::kEmergency;
  if (count_ == kQueueDepth) {
    std::move(queue_.begin() + 1, queue_.end(), queue_.begin());
    --count_;
    if (sent_ > 0) --sent_;
    ++dropped_;
  }
  queue_[count_++] = e;
  // One toggle at a time: a further toggle waits until EA acknowledges this one.
  if (!last_er_ && ea_ == en_) en_ = !en_;
}

uint64_t CnErrorSignalling::static_error_bits() const noexcept {
  return count_ > 0 ? kErrorRegisterGeneric : 0;
}

void CnErrorSignalling::status_sent() noexcept {
  sent_ = count_;
}

// ---- MN role ----------------------------------------------------------------------------------

std::string_view to_string(ErrSigState s) noexcept {
  switch (s) {
    case ErrSigState::kInitWaitEc1:
      return "init_wait_ec1";
    case ErrSigState::kInitWaitEc0:
      return "init_wait_ec0";
    case ErrSigState::kReady:
      return "ready";
    case ErrSigState::kGaveUp:
      return "no_handshake";
  }
  return "?";
}

void MnErrorSignalling::restart() noexcept {
  state_ = ErrSigState::kInitWaitEc1;
  attempts_ = 0;
  ea_ = false;
  fetch_ = false;
}

bool MnErrorSignalling::status_request_due() const noexcept {
  switch (state_) {
    case ErrSigState::kInitWaitEc1:
    case ErrSigState::kInitWaitEc0:
      return true;
    case ErrSigState::kReady:
    case ErrSigState::kGaveUp:
      return fetch_;
  }
  return false;
}

void MnErrorSignalling::on_status_request_sent() noexcept {
  if (state_ != ErrSigState::kInitWaitEc1 && state_ != ErrSigState::kInitWaitEc0) return;
  if (++attempts_ > kMaxAttempts) {
    state_ = ErrSigState::kGaveUp;
    ++gave_up_;
  }
}

void MnErrorSignalling::on_exception_new(bool en) noexcept {
  if (state_ != ErrSigState::kReady && state_ != ErrSigState::kGaveUp) return;
  if (en != ea_) fetch_ = true;
}

bool MnErrorSignalling::on_status_response(bool en, bool ec) noexcept {
  switch (state_) {
    case ErrSigState::kInitWaitEc1:
      // The answer to a request with ER=1: EC=1 means the CN has reset its signalling.
      if (ec) {
        state_ = ErrSigState::kInitWaitEc0;
        attempts_ = 0;
      }
      return false;
    case ErrSigState::kInitWaitEc0:
      // A CN that answers with the flags of the previous request shows EC=1 once more.
      if (!ec) {
        state_ = ErrSigState::kReady;
        attempts_ = 0;
        ++handshakes_;
        // EN starts from 0 after the ER edge; a CN with entries already queued toggles it.
        ea_ = false;
        if (en != ea_) {
          ea_ = en;
          return true;
        }
      }
      return false;
    case ErrSigState::kReady:
      if (ec) {
        // EC=1 again: the CN was reset behind the MN's back; initialise it again.
        restart();
        return false;
      }
      [[fallthrough]];
    case ErrSigState::kGaveUp: {
      const bool fresh = en != ea_;
      ea_ = en;
      fetch_ = false;
      return fresh;
    }
  }
  return false;
}

}  // namespace ds1928::powerlink
