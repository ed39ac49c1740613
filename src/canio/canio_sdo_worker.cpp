// The CAN-I/O driver's SDO worker (normal priority): configures each module (start-up writes,
// Rescan), checks the configuration when a node comes back after a silence, and serves the
// daemon's register requests. One expedited transfer at a time, at most one a cycle (the bus-load
// budget counts exactly that).
#include <algorithm>
#include <deque>
#include <thread>

#include "canio/canio_bus.hpp"
#include "canio/sdo_expedited.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::canio {
namespace {

template <class T>
void bump(std::atomic<T>& a, T n = 1) noexcept {
  a.store(a.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

constexpr auto kRetryConfigure = std::chrono::milliseconds(500);
// Definitive answers (aborts, read-backs that differ) before the axis goes up unverified: a node
// that answers must never keep its axis down; the PosCycle gate then decides whether it delivers.
constexpr unsigned kDefinitiveAttempts = 3;
// A register request for an axis that is being configured waits this long, then is answered
// kNotConfigured.
constexpr auto kDeferLimit = std::chrono::seconds(2);

// CiA 301 aborts that say "this object cannot be read" — the write stands, it just cannot be
// verified: 0x06010000 unsupported access, 0x06010001 attempt to read a write-only object.
[[nodiscard]] bool cannot_be_read(std::error_code ec) noexcept {
  if (ec.category() != sdo_abort_category()) return false;
  const auto code = static_cast<uint32_t>(ec.value());
  return code == 0x0601'0000 || code == 0x0601'0001;
}

// No answer at all: says nothing about the module (retried).
[[nodiscard]] bool transient(std::error_code ec) noexcept {
  return ec == CanioBusError::kSdoTimeout || ec == CanioBusError::kSdoSendFailed;
}

[[nodiscard]] std::string register_name(uint16_t reg) {
  const RegisterInfo* info = find_register(reg);
  return std::to_string(reg) + " (" + std::string(info ? info->name : "?") + ")";
}

}  // namespace

bool CanioBus::submit(const RegisterRequest& request) noexcept {
  if (!requests_.try_push(request)) return false;
  wake_.notify_one();
  return true;
}

bool CanioBus::poll(RegisterResult& out) noexcept {
  auto r = results_.try_pop();
  if (!r) return false;
  out = *r;
  return true;
}

void CanioBus::pace_sdo() noexcept {
  // At most one request per max(period, sdo_interval_us): the bus-load check (canio_timing)
  // counts exactly that on top of the cyclic frames.
  const auto period =
      std::chrono::microseconds(std::max(options_.period_us, options_.bus.sdo_interval_us));
  const auto next = last_sdo_ + period;
  const auto now = std::chrono::steady_clock::now();
  if (now < next) std::this_thread::sleep_for(next - now);
  last_sdo_ = std::chrono::steady_clock::now();
}

std::error_code CanioBus::sdo_transfer(uint8_t node, const SdoMessage& request,
                                       uint8_t expected_size, uint32_t& value,
                                       uint8_t* answered_size) {
  if (answered_size) *answered_size = 0;
  if (!sdo_port_) return make_error_code(CanioBusError::kNoAcyclicTransport);
  auto frame = build_sdo_request(node, request);
  if (!frame) return frame.error();
  // Answers to an earlier, timed-out request must not be taken for this one's.
  std::array<CanFrame, 16> rx{};
  while (sdo_port_->receive(rx, 0).count == rx.size()) {
  }
  pace_sdo();
  if (!sdo_port_->send(*frame).sent()) return make_error_code(CanioBusError::kSdoSendFailed);
  const int64_t deadline = clock_() + static_cast<int64_t>(options_.bus.sdo_timeout_ms) * 1'000'000;
  for (;;) {
    const ReceiveResult rr = sdo_port_->receive(rx, deadline);
    if (rr.error) return rr.error;
    for (std::size_t k = 0; k < rr.count; ++k) {
      if (rx[k].error || rx[k].id != kSdoResponseBase + node) continue;
      // Any size is taken here; the caller decides whether another size is an error.
      auto m = match_sdo_response(node, request, rx[k], 0);
      if (!m) return m.error();
      value = m->value;
      if (answered_size) *answered_size = m->size;
      if (expected_size != 0 && request.command == SdoCommand::UploadRequest &&
          m->size != expected_size)
        return make_error_code(SdoFrameError::kSizeMismatch);
      return {};
    }
    if (rr.count == 0 || stop_.load()) return make_error_code(CanioBusError::kSdoTimeout);
  }
}

std::error_code CanioBus::sdo_read(std::size_t axis, uint16_t reg, uint8_t size, uint32_t& value,
                                   uint8_t* answered_size) {
  const CanioAxisPlan& a = options_.axes[axis];
  const auto obj = sdo_mapping_.object_for(a.slot, reg);
  if (!obj) return make_error_code(CanioBusError::kNoSdoObject);
  SdoMessage m;
  m.command = SdoCommand::UploadRequest;
  m.index = obj->index;
  m.subindex = obj->subindex;
  bump(axis_counters_[axis].sdo_transfers);
  return sdo_transfer(a.node, m, size, value, answered_size);
}

std::error_code CanioBus::sdo_write(std::size_t axis, uint16_t reg, uint8_t size, uint32_t value,
                                    bool verify) {
  const CanioAxisPlan& a = options_.axes[axis];
  const auto obj = sdo_mapping_.object_for(a.slot, reg);
  if (!obj) return make_error_code(CanioBusError::kNoSdoObject);
  SdoMessage m;
  m.command = SdoCommand::DownloadRequest;
  m.index = obj->index;
  m.subindex = obj->subindex;
  m.size = size;
  m.value = value;
  uint32_t ignored = 0;
  bump(axis_counters_[axis].sdo_transfers);
  if (auto ec = sdo_transfer(a.node, m, 0, ignored, nullptr)) return ec;
  if (!verify || options_.bus.verify == CanVerify::None) return {};
  uint32_t back = 0;
  uint8_t back_size = 0;
  const auto ec = sdo_read(axis, reg, size, back, &back_size);
  if (cannot_be_read(ec)) {
    // The datasheet does not promise that configuration registers can be read: the write
    // was acknowledged, it stays unverified.
    bump(axis_counters_[axis].unverified);
    return {};
  }
  if (ec == SdoFrameError::kSizeMismatch) return make_error_code(CanioBusError::kReadBackSize);
  if (ec) return ec;
  if (back != value) return make_error_code(CanioBusError::kReadBackMismatch);
  return {};
}

std::error_code CanioBus::configure_axis(std::size_t axis) {
  const ModuleSettings& module = options_.axes[axis].module;
  // A read-back that differs does not stop the configuration: the write was acknowledged, the
  // remaining registers (EnDatMode last) are written all the same, and the attempt counts as a
  // definitive answer at the end. A write that is not acknowledged stops it.
  std::error_code mismatch;
  std::string mismatch_text;
  for (const RegisterWrite& w : startup_writes(module)) {
    const auto ec = sdo_write(axis, w.reg, w.size, w.value, true);
    const std::string what = "configuring the module: register " + register_name(w.reg) + " = " +
                             std::to_string(w.value) + ": " + ec.message();
    if (ec == CanioBusError::kReadBackMismatch || ec == CanioBusError::kReadBackSize) {
      if (!mismatch) {
        mismatch = ec;
        mismatch_text = what;
      }
      continue;
    }
    if (ec) {
      set_last_error(axis, what);
      return ec;
    }
  }
  if (module.endat_enable) {
    // Datasheet §11.6.2.3: EnDatAck bit 1 (Rescan) makes the module read the encoder's
    // identification again. The module boots with EnDat disabled under function model 254, so the
    // identification is read only now; the daemon's identification reads (register requests held
    // while the axis is configuring) follow.
    if (auto ec = sdo_write(axis, reg::kEnDatAck, 1, 0x02, false)) {
      set_last_error(axis, "Rescan (EnDatAck bit 1): " + ec.message());
      return ec;
    }
    bump(axis_counters_[axis].rescans);
  }
  set_last_error(axis, mismatch_text);
  return mismatch;
}

CanioBus::ConfigurationCheck CanioBus::check_configuration(std::size_t axis) {
  // verify: none — nothing is read: the module is configured again.
  if (options_.bus.verify == CanVerify::None) return ConfigurationCheck::Changed;
  const ModuleSettings& m = options_.axes[axis].module;
  const std::array<RegisterWrite, 3> checks{{{reg::kEnDatMode, 1, m.endat_mode()},
                                             {reg::kOutputMtu, 1, m.output_mtu},
                                             {reg::kInputMtu, 1, m.input_mtu}}};
  for (const RegisterWrite& c : checks) {
    uint32_t v = 0;
    uint8_t answered = 0;
    const auto ec = sdo_read(axis, c.reg, c.size, v, &answered);
    if (ec && transient(ec)) {
      // No answer proves nothing about the configuration: asked again later.
      set_last_error(axis, "checking the configuration after silence: register " +
                               register_name(c.reg) + ": " + ec.message());
      return ConfigurationCheck::Unknown;
    }
    // Any answer that is not this value of this size — another value, another size, an abort
    // (also "cannot be read": then nothing can be proven) — configures the module again.
    if (ec || answered != c.size || v != c.value) return ConfigurationCheck::Changed;
  }
  set_last_error(axis, {});
  return ConfigurationCheck::Intact;
}

void CanioBus::worker() noexcept {
  const std::size_t n = options_.axes.size();
  std::vector<std::chrono::steady_clock::time_point> retry_at(n);
  std::vector<unsigned> definitive(n, 0);
  struct Deferred {
    RegisterRequest request;
    std::chrono::steady_clock::time_point since;
  };
  std::deque<Deferred> deferred;
  if (!options_.assume_configured)
    for (std::size_t i = 0; i < n; ++i) reconfigure_[i].store(true);
  auto mark_configured = [&](std::size_t i) {
    definitive[i] = 0;
    reconfigure_[i].store(false, std::memory_order_release);
    bump(axis_counters_[i].generation);
    axis_counters_[i].configured.store(true, std::memory_order_release);
  };
  auto answer = [&](const RegisterRequest& req) {
    RegisterResult res;
    res.tag = req.tag;
    if (req.axis >= n) {
      res.error = make_error_code(CanioBusError::kNoSuchAxis);
    } else if (req.write) {
      const RegisterInfo* info = find_register(req.reg);
      // Self-clearing command registers (EnDatAck) read back 0: not verified.
      const bool verify = !(info && info->direction == RegisterDirection::Command);
      res.error = sdo_write(req.axis, req.reg, req.size, req.value, verify);
    } else {
      res.error = sdo_read(req.axis, req.reg, req.size, res.value);
    }
    if (res.error && req.axis < n) bump(axis_counters_[req.axis].sdo_errors);
    while (!results_.try_push(res) && !stop_.load())
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
  };
  while (!stop_.load()) {
    bool busy = false;
    const auto now = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < n && !stop_.load(); ++i) {
      if (!reconfigure_[i].load(std::memory_order_acquire) || now < retry_at[i]) continue;
      busy = true;
      // Back after silence: a module that kept its configuration (the node was only late or
      // disconnected) needs three reads; one that was power-cycled is configured anew. A read
      // that gets no answer (the node's SDO server not up yet, a loaded bus) proves nothing:
      // the check is repeated, and this axis publishes nothing meanwhile.
      if (axis_counters_[i].configurations.load() > 0) {
        const ConfigurationCheck check = check_configuration(i);
        if (check == ConfigurationCheck::Unknown) {
          bump(axis_counters_[i].sdo_errors);
          retry_at[i] = now + kRetryConfigure;
          continue;
        }
        if (check == ConfigurationCheck::Intact) {
          mark_configured(i);
          continue;
        }
      }
      const std::error_code ec = configure_axis(i);
      if (ec) {
        bump(axis_counters_[i].sdo_errors);
        retry_at[i] = now + kRetryConfigure;
        // The node answers, but not as written (abort, another value or size): after a few
        // attempts the axis goes up with the configuration unverified (last_error says why);
        // the PosCycle gate keeps it Stale unless the module really delivers positions.
        if (!transient(ec) && ++definitive[i] >= kDefinitiveAttempts) {
          set_last_error(i, "configured UNVERIFIED after " + std::to_string(definitive[i]) +
                                " definitive answers: " + axis_last_error(i));
          bump(axis_counters_[i].configurations);
          mark_configured(i);
        }
        continue;
      }
      bump(axis_counters_[i].configurations);
      mark_configured(i);
    }
    // Requests for an axis being configured wait (its identification needs the Rescan first).
    while (auto req = requests_.try_pop()) {
      busy = true;
      if (req->axis < n && reconfigure_[req->axis].load(std::memory_order_acquire)) {
        deferred.push_back({*req, now});
        continue;
      }
      answer(*req);
    }
    for (auto it = deferred.begin(); it != deferred.end() && !stop_.load();) {
      if (!reconfigure_[it->request.axis].load(std::memory_order_acquire)) {
        busy = true;
        answer(it->request);
        it = deferred.erase(it);
      } else if (now - it->since > kDeferLimit) {
        RegisterResult res;
        res.tag = it->request.tag;
        res.error = make_error_code(CanioBusError::kNotConfigured);
        while (!results_.try_push(res) && !stop_.load())
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        it = deferred.erase(it);
      } else {
        ++it;
      }
    }
    if (!busy) {
      std::unique_lock lock(wake_mutex_);
      wake_.wait_for(lock, std::chrono::milliseconds(20));
    }
  }
}

}  // namespace ds1928::canio
