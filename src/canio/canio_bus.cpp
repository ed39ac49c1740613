#include "canio/canio_bus.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>

#include "canio/can_error_frame.hpp"
#include "canio/can_netlink.hpp"
#include "canio/sdo_expedited.hpp"
#include "core/register_catalogue.hpp"

namespace ds1928::canio {
namespace {

int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

template <class T>
void bump(std::atomic<T>& a, T n = 1) noexcept {
  a.store(a.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

class CanioBusCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "canio-bus"; }
  [[nodiscard]] std::string message(int e) const override {
    switch (static_cast<CanioBusError>(e)) {
      case CanioBusError::kNoAcyclicTransport:
        return "no acyclic transport (canio.acyclic.transport: none): the module cannot be "
               "configured";
      case CanioBusError::kSdoTimeout:
        return "no SDO response (node silent or not a CANopen SDO server)";
      case CanioBusError::kReadBackMismatch:
        return "the register reads back another value than was written";
      case CanioBusError::kNoSdoObject:
        return "the register has no SDO object (canio.acyclic.sdo_objects)";
      case CanioBusError::kNotConfigured:
        return "the module is not configured yet";
      case CanioBusError::kSdoSendFailed:
        return "the SDO request could not be sent";
      case CanioBusError::kNoSuchAxis:
        return "no such axis";
    }
    return "unknown CAN-I/O bus error";
  }
};

constexpr auto kRetryConfigure = std::chrono::milliseconds(500);

}  // namespace

const std::error_category& canio_bus_category() noexcept {
  static const CanioBusCategory category;
  return category;
}

std::string check_interface(CanPort& port, uint32_t expected_bitrate) {
  auto info = port.query_interface();
  if (!info) return describe_link_error(port.name(), info.error());
  CanLinkInfo link;
  link.info = info.value();
  link.kind = LinkKind::Can;
  link.kind_name = "can";
  const LinkVerdict verdict = check_can_link(port.name(), link, expected_bitrate);
  return verdict.error ? verdict.message : std::string();
}

CanioBusOptions make_canio_options(const DaemonConfig& config) {
  CanioBusOptions o;
  o.bus = config.canio;
  o.period_us = config.cycle.period_us;
  for (std::size_t i = 0; i < config.axes.size(); ++i) {
    const AxisConfig& a = config.axes[i];
    CanioAxisPlan p;
    p.node = a.node;
    p.slot = a.slot;
    p.ids = canio_axis_ids(config.canio, a, i);
    p.module = a.module;
    p.name = a.name;
    o.axes.push_back(p);
  }
  return o;
}

CanioBus::CanioBus(CanioBusOptions options, std::unique_ptr<CanPort> cycle_port,
                   std::unique_ptr<CanPort> sdo_port)
    : options_(std::move(options)),
      cycle_port_(std::move(cycle_port)),
      sdo_port_(std::move(sdo_port)),
      sdo_mapping_(options_.bus.sdo_overrides),
      order_(options_.bus.little_endian ? ByteOrder::Little : ByteOrder::Big),
      pending_(options_.axes.size()),
      axis_counters_(std::make_unique<CanioAxisCounters[]>(options_.axes.size())),
      clock_(&monotonic_ns),
      last_error_(options_.axes.size()) {
  if (options_.axes.size() > kMaxCanioAxes)
    throw std::invalid_argument("canio: at most 64 axes per bus");
  for (std::size_t i = 0; i < options_.axes.size(); ++i) {
    const auto axis = static_cast<uint16_t>(i);
    routes_.push_back({options_.axes[i].ids.input[0], axis, ObjectKind::Position});
    routes_.push_back({options_.axes[i].ids.input[1], axis, ObjectKind::Status});
    if (options_.assume_configured) axis_counters_[i].configured.store(true);
  }
  std::sort(routes_.begin(), routes_.end(),
            [](const ObjectRoute& a, const ObjectRoute& b) { return a.id < b.id; });
}

CanioBus::~CanioBus() {
  stop();
}

CanInterfaceInfo CanioBus::interface_info() const {
  std::lock_guard lock(info_mutex_);
  return info_;
}

std::string CanioBus::axis_last_error(std::size_t axis) const {
  std::lock_guard lock(info_mutex_);
  return axis < last_error_.size() ? last_error_[axis] : std::string();
}

void CanioBus::set_last_error(std::size_t axis, const std::string& text) {
  std::lock_guard lock(info_mutex_);
  if (axis < last_error_.size()) last_error_[axis] = text;
}

std::error_code CanioBus::start() {
  if (!options_.assume_configured && options_.bus.acyclic == CanAcyclicTransport::None) {
    // Function model 254 boots with EnDat disabled and the MTUs unset (datasheet §11.8.1.1,
    // §11.9.4.1): without acyclic access the module can never deliver a position.
    const CanioAxisPlan& a = options_.axes.front();
    start_error_ = "axis '" + a.name + "' (node " + std::to_string(a.node) +
                   "): canio.acyclic.transport is none, but under function model 254 the module "
                   "boots with EnDat disabled (EnDatMode 0) and OutputMTU/InputMTU unset; the "
                   "daemon must write them — configure transport canopen_sdo";
    return make_error_code(CanioBusError::kNoAcyclicTransport);
  }
  std::vector<CanIdFilter> ids;
  for (const ObjectRoute& r : routes_) ids.push_back({r.id, false});
  if (auto ec = cycle_port_->set_filters(ids)) {
    start_error_ = "CAN filters on " + std::string(cycle_port_->name()) + ": " + ec.message();
    return ec;
  }
  if (auto ec = cycle_port_->set_error_mask(kDefaultErrorMask)) {
    start_error_ = "CAN error frames on " + std::string(cycle_port_->name()) + ": " + ec.message();
    return ec;
  }
  if (sdo_port_) {
    std::vector<CanIdFilter> sdo_ids;
    for (const CanioAxisPlan& a : options_.axes) {
      const CanIdFilter f{kSdoResponseBase + a.node, false};
      if (std::find(sdo_ids.begin(), sdo_ids.end(), f) == sdo_ids.end()) sdo_ids.push_back(f);
    }
    if (auto ec = sdo_port_->set_filters(sdo_ids)) {
      start_error_ = "CAN filters (SDO) on " + std::string(sdo_port_->name()) + ": " + ec.message();
      return ec;
    }
    (void)sdo_port_->set_error_mask(0);
  }
  if (auto info = cycle_port_->query_interface()) {
    std::lock_guard lock(info_mutex_);
    info_ = info.value();
  }
  state_.store(BusState::Booting, std::memory_order_relaxed);
  stop_.store(false);
  if (!options_.assume_configured || sdo_port_) worker_ = std::thread([this] { worker(); });
  return {};
}

void CanioBus::stop() noexcept {
  stop_.store(true);
  { std::lock_guard lock(wake_mutex_); }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
  state_.store(BusState::Down, std::memory_order_relaxed);
}

const CanioBus::ObjectRoute* CanioBus::route(uint32_t id) const noexcept {
  auto it = std::lower_bound(routes_.begin(), routes_.end(), id,
                             [](const ObjectRoute& r, uint32_t v) { return r.id < v; });
  return it != routes_.end() && it->id == id ? &*it : nullptr;
}

void CanioBus::count_send(SendResult r) noexcept {
  if (r.sent()) return;
  if (r.status == SendStatus::QueueFull)
    bump(counters_.tx_queue_full);
  else
    bump(counters_.tx_failed);
}

void CanioBus::handle_frame(const CanFrame& f) noexcept {
  if (f.error) {
    bump(counters_.error_frames);  // the port has applied the state change
    return;
  }
  const ObjectRoute* r = f.extended ? nullptr : route(f.id);
  if (r == nullptr) {
    bump(counters_.unexpected_ids);
    return;
  }
  CanioAxisCounters& c = axis_counters_[r->axis];
  if (f.rtr || f.dlc != kObjectBytes) {
    bump(c.wrong_length);
    return;
  }
  Pending& p = pending_[r->axis];
  bool& have = r->kind == ObjectKind::Position ? p.have_position : p.have_status;
  if (have) {
    p.ambiguous = true;  // two answers in one cycle: which belongs to this cycle is unknown
    bump(c.duplicates);
    return;
  }
  have = true;
  CanObject& dst = r->kind == ObjectKind::Position ? p.position : p.status;
  std::copy_n(f.data.begin(), kObjectBytes, dst.begin());
  if (r->kind == ObjectKind::Position) p.position_rx_ns = f.rx_time_ns;
}

ExchangeResult CanioBus::exchange(std::span<AxisIo> axes, int64_t, uint64_t) noexcept {
  ExchangeResult result;
  bump(counters_.cycles);
  const std::size_t n = std::min(axes.size(), pending_.size());
  for (std::size_t i = 0; i < n; ++i) axes[i].inputs_fresh = false;

  // Whatever is queued now arrived after the last cycle's deadline: late, never used. Error
  // frames among them move the port's state (bus-off, restarted).
  for (;;) {
    const ReceiveResult rr = cycle_port_->receive(rx_, 0);
    if (rr.error) {
      bump(counters_.receive_errors);
      break;
    }
    for (std::size_t k = 0; k < rr.count; ++k) {
      const CanFrame& f = rx_[k];
      if (f.error) {
        bump(counters_.error_frames);
        continue;
      }
      const ObjectRoute* r = f.extended ? nullptr : route(f.id);
      if (r)
        bump(axis_counters_[r->axis].late_frames);
      else
        bump(counters_.unexpected_ids);
    }
    if (rr.count < rx_.size()) break;
  }

  const CanState can = cycle_port_->state();
  if (!can_transmit(can) && can != CanState::Unknown) {
    // Bus-off or down: nothing goes out; the kernel (restart-ms) or the virtual bus restarts the
    // controller, the error frame "restarted" brings the state back.
    bump(counters_.bus_off_cycles);
    state_.store(BusState::Error, std::memory_order_relaxed);
    result.bus_up = false;
    result.frames_lost = static_cast<uint32_t>(2 * n);
    return result;
  }

  for (Pending& p : pending_) p = Pending{};
  if (options_.bus.sync_enabled) {
    CanFrame sync;
    sync.id = options_.bus.sync_id;
    sync.dlc = 0;
    const SendResult r = cycle_port_->send(sync);
    count_send(r);
    if (r.sent()) bump(counters_.sync_sent);
  }
  for (std::size_t i = 0; i < n; ++i) {
    CanFrame out;
    out.id = options_.axes[i].ids.output;
    out.dlc = kObjectBytes;
    CanObject bytes{};
    pack_output_object(axes[i].outputs, bytes);
    std::copy(bytes.begin(), bytes.end(), out.data.begin());
    count_send(cycle_port_->send(out));
  }

  // This cycle's input objects, until all are in or the response timeout ends. A receive that
  // returns nothing means the deadline has passed (or a test's clock stands still).
  const int64_t deadline = clock_() + static_cast<int64_t>(options_.bus.response_timeout_us) * 1000;
  auto complete = [&] {
    for (std::size_t i = 0; i < n; ++i)
      if (!pending_[i].have_position || !pending_[i].have_status) return false;
    return true;
  };
  while (!complete()) {
    const ReceiveResult rr = cycle_port_->receive(rx_, deadline);
    for (std::size_t k = 0; k < rr.count; ++k) handle_frame(rx_[k]);
    if (rr.error) {
      bump(counters_.receive_errors);
      break;
    }
    if (rr.count == 0) break;
  }

  const int64_t now = clock_();
  const int64_t input_timeout_ns = static_cast<int64_t>(options_.bus.input_timeout_ms) * 1'000'000;
  bool all_configured = true;
  for (std::size_t i = 0; i < n; ++i) {
    Pending& p = pending_[i];
    CanioAxisCounters& c = axis_counters_[i];
    const bool configured = c.configured.load(std::memory_order_acquire);
    all_configured &= configured;
    if (p.have_position && p.have_status && !p.ambiguous) {
      if (c.silent.load(std::memory_order_relaxed) &&
          c.last_sample_ns.load(std::memory_order_relaxed) != 0 && !options_.assume_configured) {
        // Back after silence: the node may have been power-cycled and lost its configuration
        // (EnDat disabled again). Nothing is published until the worker configured it anew.
        c.configured.store(false, std::memory_order_release);
        reconfigure_[i].store(true, std::memory_order_release);
      }
      c.silent.store(false, std::memory_order_relaxed);
      c.last_sample_ns.store(now, std::memory_order_relaxed);
      bump(c.samples);
      if (!c.configured.load(std::memory_order_acquire)) continue;
      ModuleInputs& in = axes[i].inputs;
      (void)unpack_position_object(p.position, order_, in);
      (void)unpack_status_object(p.status, in);
      axes[i].inputs_fresh = true;
      axes[i].rx_time_ns = p.position_rx_ns;
      continue;
    }
    result.frames_lost += static_cast<uint32_t>(!p.have_position) + !p.have_status;
    if (p.have_position != p.have_status)
      bump(c.half_samples);
    else if (!p.have_position)
      bump(c.missing);
    if (now - c.last_sample_ns.load(std::memory_order_relaxed) > input_timeout_ns)
      c.silent.store(true, std::memory_order_relaxed);
  }
  const BusState st = all_configured ? BusState::Operational : BusState::Booting;
  state_.store(st, std::memory_order_relaxed);
  result.bus_up = st == BusState::Operational;
  return result;
}

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

// ---- SDO worker (normal priority) -----------------------------------------------------------

std::error_code CanioBus::sdo_transfer(uint8_t node, const SdoMessage& request,
                                       uint8_t expected_size, uint32_t& value) {
  if (!sdo_port_) return make_error_code(CanioBusError::kNoAcyclicTransport);
  auto frame = build_sdo_request(node, request);
  if (!frame) return frame.error();
  // Answers to an earlier, timed-out request must not be taken for this one's.
  std::array<CanFrame, 16> rx{};
  while (sdo_port_->receive(rx, 0).count == rx.size()) {
  }
  if (!sdo_port_->send(*frame).sent()) return make_error_code(CanioBusError::kSdoSendFailed);
  const int64_t deadline = clock_() + static_cast<int64_t>(options_.bus.sdo_timeout_ms) * 1'000'000;
  for (;;) {
    const ReceiveResult rr = sdo_port_->receive(rx, deadline);
    if (rr.error) return rr.error;
    for (std::size_t k = 0; k < rr.count; ++k) {
      if (rx[k].error || rx[k].id != kSdoResponseBase + node) continue;
      auto m = match_sdo_response(node, request, rx[k], expected_size);
      if (!m) return m.error();
      value = m->value;
      return {};
    }
    if (rr.count == 0 || stop_.load()) return make_error_code(CanioBusError::kSdoTimeout);
  }
}

std::error_code CanioBus::sdo_read(std::size_t axis, uint16_t reg, uint8_t size, uint32_t& value) {
  const CanioAxisPlan& a = options_.axes[axis];
  const auto obj = sdo_mapping_.object_for(a.slot, reg);
  if (!obj) return make_error_code(CanioBusError::kNoSdoObject);
  SdoMessage m;
  m.command = SdoCommand::UploadRequest;
  m.index = obj->index;
  m.subindex = obj->subindex;
  bump(axis_counters_[axis].sdo_transfers);
  return sdo_transfer(a.node, m, size, value);
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
  if (auto ec = sdo_transfer(a.node, m, 0, ignored)) return ec;
  if (!verify) return {};
  uint32_t back = 0;
  if (auto ec = sdo_read(axis, reg, size, back)) return ec;
  if (back != value) return make_error_code(CanioBusError::kReadBackMismatch);
  return {};
}

std::error_code CanioBus::configure_axis(std::size_t axis) {
  for (const RegisterWrite& w : startup_writes(options_.axes[axis].module)) {
    if (auto ec = sdo_write(axis, w.reg, w.size, w.value, true)) {
      const RegisterInfo* info = find_register(w.reg);
      set_last_error(axis, "configuring the module: register " + std::to_string(w.reg) + " (" +
                               std::string(info ? info->name : "?") +
                               ") = " + std::to_string(w.value) + ": " + ec.message());
      return ec;
    }
  }
  set_last_error(axis, {});
  return {};
}

CanioBus::ConfigurationCheck CanioBus::check_configuration(std::size_t axis) {
  const ModuleSettings& m = options_.axes[axis].module;
  const std::array<RegisterWrite, 3> checks{{{reg::kEnDatMode, 1, m.endat_mode()},
                                             {reg::kOutputMtu, 1, m.output_mtu},
                                             {reg::kInputMtu, 1, m.input_mtu}}};
  for (const RegisterWrite& c : checks) {
    uint32_t v = 0;
    if (auto ec = sdo_read(axis, c.reg, c.size, v)) {
      const RegisterInfo* info = find_register(c.reg);
      set_last_error(axis, "checking the configuration after silence: register " +
                               std::to_string(c.reg) + " (" + std::string(info ? info->name : "?") +
                               "): " + ec.message());
      return ConfigurationCheck::Unknown;
    }
    if (v != c.value) return ConfigurationCheck::Changed;
  }
  set_last_error(axis, {});
  return ConfigurationCheck::Intact;
}

void CanioBus::worker() noexcept {
  const std::size_t n = options_.axes.size();
  std::vector<std::chrono::steady_clock::time_point> retry_at(n);
  if (!options_.assume_configured)
    for (std::size_t i = 0; i < n; ++i) reconfigure_[i].store(true);
  while (!stop_.load()) {
    bool busy = false;
    const auto now = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < n && !stop_.load(); ++i) {
      if (!reconfigure_[i].load(std::memory_order_acquire) || now < retry_at[i]) continue;
      busy = true;
      // Back after silence: a module that kept its configuration (the node was only late or
      // disconnected) needs three reads; one that was power-cycled is configured anew. A read
      // that fails (the node's SDO server not answering yet, a loaded bus) proves neither:
      // the check is repeated, and nothing is published meanwhile.
      if (axis_counters_[i].configurations.load() > 0) {
        const ConfigurationCheck check = check_configuration(i);
        if (check == ConfigurationCheck::Unknown) {
          bump(axis_counters_[i].sdo_errors);
          retry_at[i] = now + kRetryConfigure;
          continue;
        }
        if (check == ConfigurationCheck::Intact) {
          reconfigure_[i].store(false, std::memory_order_release);
          axis_counters_[i].configured.store(true, std::memory_order_release);
          continue;
        }
      }
      if (configure_axis(i)) {
        bump(axis_counters_[i].sdo_errors);
        retry_at[i] = now + kRetryConfigure;
        continue;
      }
      reconfigure_[i].store(false, std::memory_order_release);
      bump(axis_counters_[i].configurations);
      axis_counters_[i].configured.store(true, std::memory_order_release);
    }
    while (auto req = requests_.try_pop()) {
      busy = true;
      RegisterResult res;
      res.tag = req->tag;
      if (req->axis >= n) {
        res.error = make_error_code(CanioBusError::kNoSuchAxis);
      } else if (req->write) {
        const RegisterInfo* info = find_register(req->reg);
        // Self-clearing command registers (EnDatAck) read back 0: not verified.
        const bool verify = !(info && info->direction == RegisterDirection::Command);
        res.error = sdo_write(req->axis, req->reg, req->size, req->value, verify);
      } else {
        res.error = sdo_read(req->axis, req->reg, req->size, res.value);
      }
      if (res.error && req->axis < n) bump(axis_counters_[req->axis].sdo_errors);
      while (!results_.try_push(res) && !stop_.load())
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (!busy) {
      std::unique_lock lock(wake_mutex_);
      wake_.wait_for(lock, std::chrono::milliseconds(20));
    }
  }
}

}  // namespace ds1928::canio
