#include "powerlink/powerlink_bus.hpp"

#include <algorithm>
#include <cstring>

#include "core/clock.hpp"

namespace ds1928::powerlink {
namespace {

NetTime wall_clock() noexcept {
  const int64_t ns = rt::realtime_ns();
  return {static_cast<uint32_t>(ns / rt::kNsPerSec), static_cast<uint32_t>(ns % rt::kNsPerSec)};
}

}  // namespace

PowerlinkBus::PowerlinkBus(const MnConfig& config, std::unique_ptr<Link> link)
    : PowerlinkBus(config, *link) {
  owned_link_ = std::move(link);
}

PowerlinkBus::PowerlinkBus(const MnConfig& config, Link& link)
    : config_(config),
      link_(link),
      mn_(config),
      iso_end_(static_cast<int64_t>(config.cycle_us) * 1000),
      async_end_(static_cast<int64_t>(config.cycle_us) * 1000),
      clock_(&rt::now_ns) {
  axis_map_.resize(config_.axes.size());
  rx_time_.resize(config_.axes.size());
  raw_.resize(config_.bus.nodes.size());
  pres_latency_ = std::make_unique<PresLatencyHistogram[]>(raw_.size());
  Snapshot initial;
  initial.pres.resize(config_.bus.nodes.size());
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    const uint8_t node = config_.bus.nodes[i].node_id;
    raw_[i].node = initial.pres[i].node = node;
  }
  snapshot_.for_each([&](Snapshot& s) { s = initial; });
  mapped_.for_each([&](std::vector<MappedImage>& v) { v.resize(raw_.size()); });
  sync_layouts();
}

void PowerlinkBus::sync_layouts() noexcept {
  layouts_version_ = mn_.layouts_version();
  for (std::size_t i = 0; i < axis_map_.size(); ++i) {
    const AxisConfig& a = config_.axes[i];
    axis_map_[i] = {a.node, {}, false};
    const NodeImageLayout* layout = mn_.layout(a.node);
    if (!layout) continue;  // axis on an unconfigured node: never fresh
    if (const ModuleMapping* m = layout->find(a.slot)) axis_map_[i] = {a.node, *m, true};
  }
  std::vector<MappedImage>& images = mapped_.back();
  for (std::size_t i = 0; i < raw_.size() && i < images.size(); ++i) {
    MappedImage& img = images[i];
    img.node = raw_[i].node;
    if (const CnStatus* st = mn_.node(img.node)) {
      img.source = st->image_source;
      img.error = st->image_error;
      img.refusal = st->image_refusal;
    }
    if (const NodeImageLayout* layout = mn_.layout(img.node)) img.layout = *layout;
    const auto tpdo = mn_.mapped_objects(img.node, true);
    const auto rpdo = mn_.mapped_objects(img.node, false);
    img.tpdo_count = static_cast<uint16_t>(std::min(tpdo.size(), img.tpdo.size()));
    img.rpdo_count = static_cast<uint16_t>(std::min(rpdo.size(), img.rpdo.size()));
    std::copy_n(tpdo.begin(), img.tpdo_count, img.tpdo.begin());
    std::copy_n(rpdo.begin(), img.rpdo_count, img.rpdo.begin());
  }
  mapped_.publish();
}

bool PowerlinkBus::mapped_image(uint8_t node, MappedImage& out) const {
  for (const MappedImage& img : mapped_.read()) {
    if (img.node != node) continue;
    out = img;
    return true;
  }
  return false;
}

PowerlinkBus::NodeRaw* PowerlinkBus::raw(uint8_t node) noexcept {
  for (NodeRaw& r : raw_)
    if (r.node == node) return &r;
  return nullptr;
}
const PowerlinkBus::NodeRaw* PowerlinkBus::raw(uint8_t node) const noexcept {
  for (const NodeRaw& r : raw_)
    if (r.node == node) return &r;
  return nullptr;
}

const PresLatencyHistogram* PowerlinkBus::pres_latency(uint8_t node) const noexcept {
  const NodeRaw* r = raw(node);
  return r ? &pres_latency_[static_cast<std::size_t>(r - raw_.data())] : nullptr;
}

PreqWriteCheck PowerlinkBus::set_preq(uint8_t node, uint16_t offset,
                                      std::span<const uint8_t> bytes) {
  PreqWriteCheck check;
  const NodeRaw* r = raw(node);
  if (!r) {
    check.error = make_error_code(MnError::kNodeNotConfigured);
    return check;
  }
  {
    const PowerlinkStatus& st = snapshot_.read().status;
    for (std::size_t i = 0; i < st.node_count; ++i)
      if (st.nodes[i].node == node) check.preq_size = st.nodes[i].preq_size;
  }
  if (bytes.size() > kMaxPreqWrite) {
    check.error = make_error_code(MnError::kPreqWriteTooLong);
    return check;
  }
  const std::size_t end = std::size_t{offset} + bytes.size();
  if (end > check.preq_size) {
    check.error = make_error_code(MnError::kPreqOutOfRange);
    return check;
  }
  // The modules' regions as the cycle thread last bound them (a CN's own mapping read at boot
  // moves them).
  const NodeImageLayout& layout = mapped_.read()[static_cast<std::size_t>(r - raw_.data())].layout;
  for (const ModuleMapping& m : layout.mappings()) {
    if (preq_overlaps(m, offset, end)) {
      check.error = make_error_code(MnError::kPreqRegionOwnedByModule);
      check.module = m;
      return check;
    }
  }
  PreqWrite w;
  w.node = node;
  w.offset = offset;
  w.length = static_cast<uint16_t>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), w.bytes.begin());
  if (!preq_writes_.try_push(w)) check.error = make_error_code(MnError::kQueueFull);
  return check;
}

void PowerlinkBus::apply_preq_writes() noexcept {
  while (auto w = preq_writes_.try_pop()) {
    NodeRaw* r = raw(w->node);
    // Checked by set_preq(); the image is kMaxIsoPayload bytes whatever the CN's size is now.
    if (!r || std::size_t{w->offset} + w->length > kMaxIsoPayload || w->length == 0) continue;
    std::memcpy(r->preq_set.data() + w->offset, w->bytes.data(), w->length);
    for (std::size_t i = 0; i < w->length; ++i) r->preq_mask.set(w->offset + i);
    const auto hi = static_cast<uint16_t>(w->offset + w->length);
    if (r->set_lo == r->set_hi) {
      r->set_lo = w->offset;
      r->set_hi = hi;
    } else {
      r->set_lo = std::min(r->set_lo, w->offset);
      r->set_hi = std::max(r->set_hi, hi);
    }
  }
}

std::error_code PowerlinkBus::start() {
  // A link without carrier is waited for (a cable plugged in later, an interface brought up):
  // exchange() sends nothing until it is up, and the status says so (link_up false).
  state_.store(BusState::Booting, std::memory_order_relaxed);
  publish_status();
  return {};
}

void PowerlinkBus::stop() noexcept {
  state_.store(BusState::Down, std::memory_order_relaxed);
}

void PowerlinkBus::send(Result<std::size_t> len) noexcept {
  if (len && *len > 0) (void)link_.send(std::span<const uint8_t>(tx_.data(), *len));
}

void PowerlinkBus::drain(int64_t deadline_ns) noexcept {
  for (;;) {
    Received r = link_.receive(rx_, deadline_ns);
    if (r.length == 0 || r.error) return;
    (void)mn_.on_frame(std::span<const uint8_t>(rx_.data(), r.length));
  }
}

ExchangeResult PowerlinkBus::exchange(std::span<AxisIo> axes, int64_t cycle_start_ns,
                                      uint64_t) noexcept {
  ExchangeResult result;
  for (AxisIo& io : axes) io.inputs_fresh = false;
  if (!link_.link_up()) {
    state_.store(BusState::Error, std::memory_order_relaxed);
    publish_status();
    return result;
  }
  // Register requests from the normal thread become SDO transfers. One the node's SDO queue has
  // no room for yet stays queued (in order) until it has: a burst longer than the node's queue
  // (the identification reads 44 registers) waits instead of failing.
  registers().serve(*this);

  apply_preq_writes();
  for (NodeRaw& r : raw_) r.pres_fresh = false;

  mn_.begin_cycle(cycle_start_ns);
  // Whatever arrived since the last cycle's end is late: a PRes among it would otherwise be taken
  // for this cycle's answer (frames carry no cycle number). The MN drops such PRes (counted as
  // stale); late ASnds are still served, they identify themselves (SDO sequence numbers).
  drain(0);
  if (mn_.not_active()) {
    // Listening for another MN (MNWaitNotAct): nothing is sent.
    mn_.not_active_cycle();
    state_.store(mn_.counters().foreign_mn_at_start ? BusState::Error : BusState::Booting,
                 std::memory_order_relaxed);
    publish_status();
    return result;
  }
  // A CN's own mapping was read and bound at boot: its axes move to where it puts them.
  if (mn_.layouts_version() != layouts_version_) sync_layouts();
  const std::size_t n_axes = std::min(axes.size(), axis_map_.size());
  for (NodeRaw& r : raw_) r.outputs_ok = true;
  for (std::size_t i = 0; i < n_axes; ++i) {
    const AxisMap& am = axis_map_[i];
    if (am.valid && !write_outputs(mn_.preq_payload(am.node), am.mapping, axes[i].outputs))
      if (NodeRaw* r = raw(am.node)) r->outputs_ok = false;  // payload smaller than its image
    rx_time_[i] = 0;
  }
  // A node's PReq (or the PResMN for a chained one) says RD = 1 only with its whole image
  // written; bytes set through set_preq() are copied in before each PReq.
  for (const NodeRaw& r : raw_)
    if (r.outputs_ok) mn_.outputs_written(r.node);
  int64_t soc_ns = -1;
  iso_end_ns_ = 0;
  if (mn_.full_cycle()) {
    // RelativeTime and the NetTimeRef describe the instant the SoC leaves, which is the cycle
    // thread's wake-up latency (tens of µs, ms in a stall) after the nominal cycle start.
    soc_ns = clock_();
    iso_end_ns_ = soc_ns;
    mn_.stamp_soc(soc_ns, wall_clock());
    send(mn_.build_soc(tx_));
    // WaitSoCPReq: the CNs get this long to take the SoC before the first PReq; frames that come
    // meanwhile (late ASnds) are served, and the wait is the link's (blocking by default).
    if (config_.bus.wait_soc_preq_us > 0 &&
        (!mn_.isochronous_nodes().empty() || !mn_.prc_nodes().empty()))
      drain(soc_ns + static_cast<int64_t>(config_.bus.wait_soc_preq_us) * 1000);
    if (!mn_.prc_nodes().empty()) prc_slot(result, n_axes);
  }
  for (uint8_t node : mn_.isochronous_nodes()) {
    const CnStatus* st = mn_.node(node);
    const uint32_t before = st->pres_received;
    NodeRaw* nr = raw(node);
    if (nr && nr->set_lo < nr->set_hi) {
      // Set bytes are written every cycle: the MN clears the image when the CN is identified
      // again, and the axes' bytes never overlap them (set_preq() refuses that).
      std::span<uint8_t> preq = mn_.preq_payload(node);
      const std::size_t hi = std::min<std::size_t>(nr->set_hi, preq.size());
      for (std::size_t b = nr->set_lo; b < hi; ++b)
        if (nr->preq_mask.test(b)) preq[b] = nr->preq_set[b];
    }
    drain(0);  // the late PRes of an earlier PReq to this node must not pass for this one's
    const int64_t preq_ns = clock_();
    send(mn_.build_preq(node, tx_));
    const int64_t deadline = clock_() + static_cast<int64_t>(mn_.pres_timeout_us(node)) * 1000;
    for (;;) {
      Received r = link_.receive(rx_, deadline);
      if (r.length == 0 || r.error) {
        mn_.on_pres_timeout(node);
        iso_end_ns_ = std::max(iso_end_ns_, deadline);
        ++result.frames_lost;
        break;
      }
      (void)mn_.on_frame(std::span<const uint8_t>(rx_.data(), r.length));
      if (st->pres_received != before) {
        note_pres(node, r.rx_time_ns ? r.rx_time_ns : clock_(), preq_ns, n_axes);
        break;
      }
    }
  }
  send(mn_.build_soa(tx_));
  send(mn_.build_mn_asnd(tx_));
  if (mn_.awaiting_asnd()) {
    const int64_t deadline = clock_() + static_cast<int64_t>(config_.bus.async_timeout_us) * 1000;
    while (mn_.awaiting_asnd()) {
      Received r = link_.receive(rx_, deadline);
      if (r.length == 0 || r.error) {
        mn_.on_async_timeout();
        break;
      }
      (void)mn_.on_frame(std::span<const uint8_t>(rx_.data(), r.length));
    }
  }
  drain(0);  // late and foreign frames
  const int64_t period_ns = static_cast<int64_t>(config_.cycle_us) * 1000;
  const int64_t end_ns = clock_();
  mn_.end_cycle(end_ns - cycle_start_ns > period_ns);
  if (soc_ns >= 0) {
    if (iso_end_ns_ > soc_ns) iso_end_.record(iso_end_ns_ - soc_ns);  // a CN was polled
    async_end_.record(end_ns - soc_ns);
  }
  if (mn_.layouts_version() != layouts_version_) sync_layouts();

  for (std::size_t i = 0; i < n_axes; ++i) {
    const AxisMap& am = axis_map_[i];
    if (!am.valid || !mn_.pres_fresh(am.node)) continue;
    const CnStatus* st = mn_.node(am.node);
    if (st->boot != CnBootState::kOperational) continue;
    if (read_inputs(mn_.pres_payload(am.node), am.mapping, axes[i].inputs)) {
      axes[i].inputs_fresh = true;
      axes[i].rx_time_ns = rx_time_[i];
    }
  }
  RegisterResult r;
  while (registers().flush() && mn_.poll(r)) (void)registers().complete(r);

  // Another MN's frames while running: one incident per run of cycles that saw them.
  const uint32_t foreign = mn_.counters().foreign_mn_frames;
  if (foreign != foreign_mn_frames_ && !foreign_mn_seen_) raise_incident(IncidentKind::ForeignMn);
  foreign_mn_seen_ = foreign != foreign_mn_frames_;
  foreign_mn_frames_ = foreign;

  result.net_time = {mn_.net_time_us(), mn_.soc_time_ns(), mn_.full_cycle()};
  result.bus_up = mn_.all_operational();
  state_.store(result.bus_up ? BusState::Operational : BusState::Booting,
               std::memory_order_relaxed);
  publish_status();
  return result;
}

void PowerlinkBus::note_pres(uint8_t node, int64_t t, int64_t sent_ns,
                             std::size_t n_axes) noexcept {
  for (std::size_t i = 0; i < n_axes; ++i)
    if (axis_map_[i].node == node) rx_time_[i] = t;
  iso_end_ns_ = std::max(iso_end_ns_, t);
  if (NodeRaw* nr = raw(node)) {
    pres_latency_[static_cast<std::size_t>(nr - raw_.data())].record(t - sent_ns);
    nr->pres_fresh = nr->pres_received = true;
    if (const CnStatus* st = mn_.node(node)) nr->pres_ready = st->pres_ready;
    nr->pres_rx_ns = t;
    nr->pres_cycle = mn_.counters().cycles;
  }
}

void PowerlinkBus::prc_slot(ExchangeResult& result, std::size_t n_axes) noexcept {
  // PollResponse Chaining: one PResMN, then every PRC node's PRes at its own time after it, no
  // PReq. The slot ends when all came or at its end (the last PRes time, its PRes on the wire and
  // the longest PRes timeout); a PRes still missing then is lost.
  const std::span<const uint8_t> nodes = mn_.prc_nodes();
  drain(0);  // a PRes found now answered an earlier PResMN
  const int64_t sent_ns = clock_();
  send(mn_.build_pres_mn(tx_));
  // The slot counts from the clock read after the send: a cycle thread preempted between the
  // read and the send put the PResMN (the CNs' time reference) on the wire late, and the PRC
  // PRes with it; a deadline from the earlier read would count that lateness of the MN as the
  // CNs' loss.
  const int64_t deadline = clock_() + mn_.prc_slot_ns();
  std::size_t pending = nodes.size();
  while (pending > 0) {
    Received r = link_.receive(rx_, deadline);
    if (r.length == 0 || r.error) break;
    const uint8_t src = r.length > 16 ? rx_[16] : 0;
    const CnStatus* st = mn_.node(src);
    const uint32_t before = st ? st->pres_received : 0;
    (void)mn_.on_frame(std::span<const uint8_t>(rx_.data(), r.length));
    if (st && st->pres_received != before && st->prc) {
      note_pres(src, r.rx_time_ns ? r.rx_time_ns : clock_(), sent_ns, n_axes);
      --pending;
    }
  }
  for (uint8_t node : nodes) {
    if (mn_.pres_seen(node)) continue;
    mn_.on_pres_timeout(node);
    iso_end_ns_ = std::max(iso_end_ns_, deadline);
    ++result.frames_lost;
  }
}

void PowerlinkBus::publish_status() noexcept {
  // Never waits for the reader: the triple buffer always has a free buffer for the cycle thread.
  Snapshot& snap = snapshot_.back();
  PowerlinkStatus& st = snap.status;
  st.mn_state = mn_.mn_state();
  st.counters = mn_.counters();
  st.link_up = link_.link_up();
  const auto nodes = mn_.nodes();
  st.node_count = std::min(nodes.size(), st.nodes.size());
  std::copy_n(nodes.begin(), st.node_count, st.nodes.begin());
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    const NodeRaw& r = raw_[i];
    PresSnapshot& p = snap.pres[i];
    p.fresh = r.pres_fresh;
    p.ready = r.pres_ready;
    p.received = r.pres_received;
    p.cycle = r.pres_cycle;
    p.rx_time_ns = r.pres_rx_ns;
    // The MN keeps the last PRes payload until the next one arrives.
    const std::span<const uint8_t> bytes = mn_.pres_payload(r.node);
    p.size = static_cast<uint16_t>(std::min(bytes.size(), p.payload.size()));
    std::copy_n(bytes.begin(), p.size, p.payload.begin());
  }
  snapshot_.publish();
}

bool PowerlinkBus::pres_snapshot(uint8_t node, PresSnapshot& out) const {
  for (const PresSnapshot& p : snapshot_.read().pres) {
    if (p.node != node) continue;
    out = p;
    return true;
  }
  return false;
}

PowerlinkStatus PowerlinkBus::status() const {
  return snapshot_.read().status;
}

RegisterTarget::Offer PowerlinkBus::offer(const RegisterRequest& request) noexcept {
  if (request.axis >= axis_map_.size() || !axis_map_[request.axis].valid) {
    (void)registers().complete({request.tag, make_error_code(MnError::kNodeNotConfigured), 0});
    return Offer::kTaken;
  }
  const AxisMap& am = axis_map_[request.axis];
  if (!mn_.can_submit(am.node)) return Offer::kWait;
  if (!mn_.submit(am.node, am.mapping.slot, request))
    (void)registers().complete({request.tag, make_error_code(MnError::kQueueFull), 0});
  return Offer::kTaken;
}

}  // namespace ds1928::powerlink
