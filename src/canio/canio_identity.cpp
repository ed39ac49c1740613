// The CAN-I/O driver's node identity check (docs/canio.md §Node identity): before a node's
// modules are configured, and again after each boot-up (a node replaced sends one) and each
// silence, the expected objects of canio.nodes[] (0x1000 device type, 0x1018/1..4) are read over
// expedited SDO, one transfer per object, as a job of the register access state machine
// (canio_sdo.cpp) on the cycle thread. A node that differs — or cannot answer for an expected
// object (an abort: the object does not exist) — is not configured and not started with
// topology.on_mismatch refuse: its axes stay down (IdentityMismatch) and the check is repeated
// with back-off, so a corrected node recovers; with warn it is reported and configured all the
// same. No allocation, no lock: the result goes out under a sequence counter and as an event.
#include <algorithm>
#include <array>
#include <cstdio>

#include "canio/canio_bus.hpp"
#include "core/single_writer.hpp"

namespace ds1928::canio {
namespace {

constexpr int64_t kMs = 1'000'000;
// A node that differs is asked again after 0.5, 1, 2, ... s, at most 30 s (the back-off of an
// unconfigurable axis); a boot-up starts again at 0.5 s.
constexpr int64_t kIdentityRetryFirstNs = 500 * kMs;
constexpr int64_t kIdentityRetryMaxNs = 30'000 * kMs;

[[nodiscard]] bool transient(std::error_code ec) noexcept {
  return ec == CanioBusError::kSdoTimeout || ec == CanioBusError::kSdoSendFailed;
}

}  // namespace

std::string_view to_string(NodeIdentityState s) noexcept {
  switch (s) {
    case NodeIdentityState::Unchecked:
      return "unchecked";
    case NodeIdentityState::Pending:
      return "pending";
    case NodeIdentityState::Confirmed:
      return "confirmed";
    case NodeIdentityState::Mismatch:
      return "mismatch";
    case NodeIdentityState::Unreadable:
      return "unreadable";
  }
  return "?";
}

std::string describe_identity(const NodeIdentity& id) {
  std::string out;
  for (std::size_t f = 0; f < kIdentityFields.size(); ++f) {
    const unsigned bit = 1U << f;
    if ((id.expected_mask & bit) == 0) continue;
    const IdentityField& k = kIdentityFields[f];
    std::array<char, 96> buf{};
    std::string d;
    if ((id.unreadable_mask & bit) != 0) {
      std::snprintf(buf.data(), buf.size(),
                    " unreadable, expected 0x%08X (0x%04X/%u: ", id.expected[f], unsigned{k.index},
                    unsigned{k.subindex});
      d = std::string(k.key) + buf.data() +
          (id.error ? id.error.message() : std::string("refused")) + ")";
    } else if ((id.read_mask & bit) != 0 && id.found[f] != id.expected[f]) {
      std::snprintf(buf.data(), buf.size(), " 0x%08X, expected 0x%08X (0x%04X/%u)", id.found[f],
                    id.expected[f], unsigned{k.index}, unsigned{k.subindex});
      d = std::string(k.key) + buf.data();
    }
    if (!d.empty()) out += (out.empty() ? "identity: " : "; ") + d;
  }
  return out;
}

NodeIdentity CanioBus::node_identity(std::size_t k) const noexcept {
  NodeIdentity id;
  if (k >= nodes_.size()) return id;
  // The expectation is fixed after construction.
  id.expected_mask = nodes_[k].identity_mask;
  id.expected = nodes_[k].identity_expected;
  const CanioNodeCounters& c = node_counters_[k];
  for (;;) {
    const uint32_t before = c.identity_seq.load(std::memory_order_acquire);
    id.state = static_cast<NodeIdentityState>(c.identity_state.load(std::memory_order_acquire));
    id.read_mask = c.identity_read.load(std::memory_order_acquire);
    id.unreadable_mask = c.identity_unreadable.load(std::memory_order_acquire);
    for (std::size_t f = 0; f < id.found.size(); ++f)
      id.found[f] = c.identity_found[f].load(std::memory_order_acquire);
    const int code = c.identity_error.load(std::memory_order_acquire);
    const std::error_category* cat = c.identity_category.load(std::memory_order_acquire);
    id.error = cat ? std::error_code(code, *cat) : std::error_code();
    id.checks = c.identity_checks.load(std::memory_order_acquire);
    id.mismatches = c.identity_mismatches.load(std::memory_order_acquire);
    if ((before & 1U) == 0 && c.identity_seq.load(std::memory_order_acquire) == before) return id;
  }
}

void CanioBus::publish_identity(std::size_t k) noexcept {
  const NodeTrack& t = nodes_[k];
  CanioNodeCounters& c = node_counters_[k];
  const uint32_t s = c.identity_seq.load(std::memory_order_relaxed);
  c.identity_seq.store(s + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  c.identity_state.store(static_cast<uint8_t>(t.identity_state), std::memory_order_release);
  c.identity_read.store(t.id_read, std::memory_order_release);
  c.identity_unreadable.store(t.id_unreadable, std::memory_order_release);
  for (std::size_t f = 0; f < t.id_found.size(); ++f)
    c.identity_found[f].store(t.id_found[f], std::memory_order_release);
  c.identity_error.store(t.id_error.value(), std::memory_order_release);
  c.identity_category.store(t.id_error ? &t.id_error.category() : nullptr,
                            std::memory_order_release);
  c.identity_seq.store(s + 2, std::memory_order_release);
}

bool CanioBus::identity_refused(std::size_t k) const noexcept {
  const NodeIdentityState s = nodes_[k].identity_state;
  return options_.identity_refuse &&
         (s == NodeIdentityState::Mismatch || s == NodeIdentityState::Unreadable);
}

bool CanioBus::start_identity(std::size_t axis) noexcept {
  NodeTrack& t = nodes_[axis_node_[axis]];
  if (t.identity_mask == 0) return false;
  job_ = SdoJob{};
  job_.kind = SdoJobKind::Identity;
  job_.axis = static_cast<uint16_t>(axis);
  job_.stage = SdoStage::Read;
  // The first expected object.
  while (job_.step < kIdentityFields.size() && (t.identity_mask & (1U << job_.step)) == 0)
    ++job_.step;
  t.id_read = 0;
  t.id_unreadable = 0;
  t.id_found = {};
  t.id_error = {};
  return true;
}

void CanioBus::identity_step_done(int64_t now, std::error_code ec, uint32_t value) noexcept {
  const std::size_t axis = job_.axis;
  NodeTrack& t = nodes_[axis_node_[axis]];
  if (ec && transient(ec)) {
    // No answer says nothing about who is there: asked again later, the node's axes wait.
    single_writer_add(axis_counters_[axis].sdo_errors);
    job_.kind = SdoJobKind::None;
    for (std::size_t i = 0; i < axis_node_.size(); ++i)
      if (axis_node_[i] == axis_node_[axis]) axis_sdo_[i].retry_at_ns = now + kIdentityRetryFirstNs;
    return;
  }
  const unsigned bit = 1U << job_.step;
  if (ec) {
    // Refused (an abort: "object does not exist", or an answer that is not this read's): an
    // expected object the node cannot show is a mismatch, never a pass.
    t.id_unreadable = static_cast<uint8_t>(t.id_unreadable | bit);
    if (!t.id_error) t.id_error = ec;
  } else {
    t.id_read = static_cast<uint8_t>(t.id_read | bit);
    t.id_found[job_.step] = value;
  }
  do {
    ++job_.step;
  } while (job_.step < kIdentityFields.size() && (t.identity_mask & (1U << job_.step)) == 0);
  if (job_.step < kIdentityFields.size()) return;
  finish_identity(now);
}

void CanioBus::finish_identity(int64_t now) noexcept {
  const std::size_t axis = job_.axis;
  const std::size_t k = axis_node_[axis];
  NodeTrack& t = nodes_[k];
  CanioNodeCounters& c = node_counters_[k];
  job_.kind = SdoJobKind::None;
  bool differs = false;
  for (std::size_t f = 0; f < kIdentityFields.size(); ++f)
    if ((t.id_read & (1U << f)) != 0 && t.id_found[f] != t.identity_expected[f]) differs = true;
  const NodeIdentityState before = t.identity_state;
  t.identity_state = t.id_unreadable != 0 ? NodeIdentityState::Unreadable
                     : differs            ? NodeIdentityState::Mismatch
                                          : NodeIdentityState::Confirmed;
  single_writer_add(c.identity_checks);
  const bool bad = t.identity_state != NodeIdentityState::Confirmed;
  if (bad) single_writer_add(c.identity_mismatches);
  publish_identity(k);
  // The journal hears of a change (and of every mismatch a boot-up brought), not of each retry.
  const bool was_bad =
      before == NodeIdentityState::Mismatch || before == NodeIdentityState::Unreadable;
  if (bad && !was_bad)
    push_event({CanioNodeEventKind::IdentityMismatch, t.node, now, {}, 0});
  else if (!bad && was_bad)
    push_event({CanioNodeEventKind::IdentityConfirmed, t.node, now, {}, 0});

  if (bad && options_.identity_refuse) {
    // Not configured, not started: every axis of the node waits for the next check (a corrected
    // or replaced node recovers at it; its boot-up starts the back-off again).
    t.identity_backoff_ns = t.identity_backoff_ns == 0
                                ? kIdentityRetryFirstNs
                                : std::min(2 * t.identity_backoff_ns, kIdentityRetryMaxNs);
    for (std::size_t i = 0; i < axis_node_.size(); ++i) {
      if (axis_node_[i] != k) continue;
      axis_sdo_[i].retry_at_ns = now + t.identity_backoff_ns;
      axis_counters_[i].configured.store(false, std::memory_order_release);
    }
    return;
  }
  // As expected (or warn): the node's modules are configured (or checked) next, this axis first.
  t.identity_due = false;
  t.identity_backoff_ns = 0;
  next_axis_ = axis;
}

}  // namespace ds1928::canio
