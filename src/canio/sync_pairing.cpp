#include "canio/sync_pairing.hpp"

namespace ds1928::canio {
namespace {

void inc(uint8_t& n) noexcept {
  if (n < 255) ++n;
}

}  // namespace

void SyncPairing::late_before(ObjectKind kind) noexcept {
  // W3: an object 1 arriving before the window answers SYNC n−1 at the latest: nothing owed.
  if (kind == ObjectKind::Position) owed1_ = false;
}

void SyncPairing::open() noexcept {
  n1_ = n2_ = n2_after_ = n2_before_ = n1_after_ = 0;
  owed1_at_open_ = owed1_;
  surplus_ = false;
  position_rx_ns_ = 0;
}

void SyncPairing::in_window(ObjectKind kind, const CanObject& bytes, int64_t rx_ns) noexcept {
  if (kind == ObjectKind::Position) {
    inc(n1_);
    position_ = bytes;
    position_rx_ns_ = rx_ns;
    // Objects 2 so far precede this object 1: by W1 none of them answers its SYNC.
    n2_before_ = static_cast<uint8_t>(n2_before_ + n2_after_);
    n2_after_ = 0;
    return;
  }
  if (kind != ObjectKind::Status) return;
  inc(n2_);
  if (n1_ == 0) {
    inc(n2_before_);
    return;
  }
  inc(n2_after_);
  status_ = bytes;
}

void SyncPairing::late_after(ObjectKind kind) noexcept {
  if (kind == ObjectKind::Position) inc(n1_after_);
}

PairingVerdict SyncPairing::close(bool sync_sent) noexcept {
  // Still owed when the window opened and not paid by an object 1 stamped before it.
  const unsigned want1 = 1u + (owed1_at_open_ && owed1_ ? 1u : 0u);
  surplus_ = n1_ > want1 || n2_after_ > 1;

  PairingVerdict v;
  if (n1_ == 0 && n2_ == 0)
    v = PairingVerdict::Missing;
  else if (n1_ == want1 && n2_after_ == 1)
    v = PairingVerdict::Whole;
  else if (n1_ == 0 || n2_after_ == 0)
    v = PairingVerdict::Half;
  else
    v = PairingVerdict::Ambiguous;

  // W3: the next window can only receive this SYNC's object 1, and only if none came (an object 1
  // that came, even as one of two, is taken as this SYNC's: a lost object 1 cannot be told from
  // one that is two cycles late, which W3 excludes).
  owed1_ = sync_sent && unsigned{n1_} + n1_after_ == 0;
  return v;
}

}  // namespace ds1928::canio
