// The Managing Node (PowerlinkBus) against the simulated CN (sim::PowerlinkCn) in one process:
// an in-memory link hands every frame the MN sends to the CN at once and queues the CN's answers
// for the MN. Time is simulated, so the whole boot, a power cycle and PRes loss run in
// milliseconds and deterministically.
#include <catch2/catch.hpp>
#include <cmath>
#include <deque>
#include <functional>
#include <vector>

#include "core/axis_sample.hpp"
#include "powerlink/link.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "shm/publisher.hpp"
#include "sim/powerlink_cn.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace pl = ds1928::powerlink;
namespace sim = ds1928::sim;

namespace {

int64_t g_now_ns = 1'000'000'000;
int64_t fake_clock() noexcept {
  return g_now_ns;
}

constexpr int64_t kCycleNs = 1'000'000;
constexpr int64_t kWireNs = 2'000;  // each frame takes this long to arrive

class WireToCn final : public pl::Link {
 public:
  std::vector<sim::PowerlinkCn*> nodes;
  std::deque<std::vector<uint8_t>> to_mn;

  std::vector<uint8_t> last_preq;  // payload of the last PReq on the wire

  std::error_code send(std::span<const uint8_t> frame) noexcept override {
    g_now_ns += kWireNs;
    if (auto f = pl::parse_frame(frame))
      if (const auto* preq = std::get_if<pl::PReq>(&f->message))
        last_preq.assign(preq->payload.begin(), preq->payload.end());
    for (auto* n : nodes) n->receive(frame, g_now_ns);
    return {};
  }
  pl::Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override {
    if (to_mn.empty()) {
      if (deadline_ns > g_now_ns) g_now_ns = deadline_ns;
      return {};
    }
    auto f = std::move(to_mn.front());
    to_mn.pop_front();
    const std::size_t n = std::min(f.size(), buffer.size());
    std::copy_n(f.begin(), n, buffer.begin());
    g_now_ns += kWireNs;
    return {n, g_now_ns, {}};
  }
  bool link_up() const noexcept override { return true; }
  pl::MacAddress mac() const noexcept override { return {0x02, 0, 0, 0, 0, 0xF0}; }
};

struct Setup {
  ds1928::PowerlinkBusConfig bus;
  std::vector<ds1928::AxisConfig> axes;
  WireToCn wire;
  std::unique_ptr<sim::PowerlinkCn> cn;
  std::unique_ptr<pl::PowerlinkBus> mn;
  std::vector<ds1928::AxisIo> io;
  uint64_t cycle = 0;

  explicit Setup(const sim::PowerlinkCnFaults& faults = {}, uint32_t loss_threshold = 15,
                 const std::function<void(ds1928::PowerlinkNodeConfig&)>& node_config = {},
                 const std::function<void(sim::PowerlinkCnConfig&)>& cn_setup = {},
                 std::vector<uint8_t> slots = {1}) {
    bus.thresholds.loss_of_pres = loss_threshold;
    ds1928::PowerlinkNodeConfig node;
    node.node_id = 1;
    node.pres_timeout_us = 100;
    if (node_config) node_config(node);
    bus.nodes.push_back(node);
    for (uint8_t slot : slots) {
      ds1928::AxisConfig axis;
      axis.node = 1;
      axis.slot = slot;
      axes.push_back(axis);
    }

    sim::PowerlinkCnConfig cn_config;
    cn_config.node_id = 1;
    cn_config.faults = faults;
    cn_config.power_off_ns = 50'000'000;
    if (cn_setup) cn_setup(cn_config);
    cn = std::make_unique<sim::PowerlinkCn>(cn_config, [this](std::span<const uint8_t> f) {
      wire.to_mn.emplace_back(f.begin(), f.end());
    });
    wire.nodes.push_back(cn.get());

    pl::MnConfig mn_config;
    mn_config.bus = bus;
    mn_config.axes = axes;
    mn_config.cycle_us = 1000;
    mn_config.mac = wire.mac();
    // Listening for another MN first (MNWaitNotAct) has tests of its own; these start at once.
    mn_config.bus.nmt.wait_not_active_ms = 0;
    mn = std::make_unique<pl::PowerlinkBus>(mn_config, wire);
    mn->set_clock(&fake_clock);
    REQUIRE_FALSE(mn->start());
    io.resize(axes.size());
  }

  ds1928::ExchangeResult step() {
    const int64_t start = (g_now_ns / kCycleNs + 1) * kCycleNs;
    g_now_ns = start;
    cn->tick(g_now_ns);
    auto r = mn->exchange(io, start, cycle++);
    cn->tick(g_now_ns);
    return r;
  }
  // Cycles until the bus reports all CNs operational; false after `limit` cycles.
  bool run_until_operational(int limit) {
    for (int i = 0; i < limit; ++i)
      if (step().bus_up) return true;
    return false;
  }
};

}  // namespace

TEST_CASE("MN boots the simulated CN to OPERATIONAL in process and receives moving positions") {
  Setup s;
  REQUIRE(s.run_until_operational(3000));
  CHECK(s.cn->nmt_state() == pl::NmtState::kOperational);
  // The MN configured the module by SDO: EnDat is enabled (the simulator's default is off).
  uint32_t mode = 0;
  REQUIRE_FALSE(s.cn->module(0).read_register(ds1928::reg::kEnDatMode, 1, mode));
  CHECK(mode == s.axes[0].module.endat_mode());

  ds1928::AxisDecodeState state;
  const ds1928::AxisDecodeParams params;
  double first = 0, last = 0;
  int64_t first_t = 0, last_t = 0;
  int fresh = 0;
  for (int i = 0; i < 200; ++i) {
    auto r = s.step();
    REQUIRE(r.bus_up);
    auto sample = ds1928::decode_axis(s.io[0], params, r.net_time, state);
    REQUIRE(sample.fresh);
    REQUIRE(sample.time_source == ds1928::TimeSource::NetTime);
    const double pos = static_cast<double>(sample.periods) + sample.fraction / 65536.0;
    if (fresh == 0) {
      first = pos;
      first_t = sample.pos_time_ns;
    }
    last = pos;
    last_t = sample.pos_time_ns;
    ++fresh;
  }
  // Default motion: 100 periods/s; positions and NetTime stamps must agree.
  const double dt = static_cast<double>(last_t - first_t) / 1e9;
  CHECK(dt > 0.15);
  CHECK(std::fabs((last - first) - 100.0 * dt) < 0.02);
}

TEST_CASE("MN detects a power-cycled simulated CN and boots it again") {
  Setup s;
  REQUIRE(s.run_until_operational(3000));
  s.cn->power_cycle(g_now_ns);
  bool left = false;
  for (int i = 0; i < 100 && !left; ++i) left = !s.step().bus_up;
  REQUIRE(left);
  REQUIRE(s.run_until_operational(5000));
  CHECK(s.cn->stats().power_cycles == 1);
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  REQUIRE(st != nullptr);
  CHECK(st->boots >= 2);
  CHECK(st->resets >= 1);
}

TEST_CASE("With random PRes loss the MN never hands out stale inputs as fresh") {
  sim::PowerlinkCnFaults faults;
  faults.drop_pres = 0.05;
  faults.seed = 3;
  // Threshold 64: at the default 15 two losses within two cycles reset the CN by design.
  Setup s(faults, 64);
  REQUIRE(s.run_until_operational(5000));
  uint64_t lost = 0, fresh = 0;
  uint32_t last_pos_time = 0;
  for (int i = 0; i < 2000; ++i) {
    const uint64_t dropped_before = s.cn->stats().pres_dropped;
    auto r = s.step();
    const bool dropped = s.cn->stats().pres_dropped != dropped_before;
    if (dropped) {
      ++lost;
      CHECK_FALSE(s.io[0].inputs_fresh);
    } else if (r.bus_up && s.io[0].inputs_fresh) {
      ++fresh;
      CHECK(s.io[0].inputs.pos_time_us != last_pos_time);  // a new EnDat cycle every ms
      last_pos_time = s.io[0].inputs.pos_time_us;
    }
  }
  CHECK(lost > 50);
  CHECK(fresh > 1800);
  CHECK(s.mn->managing_node().node(1)->resets == 0);
}

TEST_CASE("PRes with RD = 0 from the simulated CN for 100 cycles publish no valid sample") {
  Setup s;
  REQUIRE(s.run_until_operational(3000));
  ds1928::AxisDecodeState state;
  const ds1928::AxisDecodeParams params;
  auto validity = [&](const ds1928::ExchangeResult& r) {
    ds1928::AxisSample sample = ds1928::decode_axis(s.io[0], params, r.net_time, state);
    const ds1928::ErrorWords words{sample.error_info, 0, 0};
    const ds1928::ErrorAssessment errors =
        ds1928::apply_error_policy(sample, ds1928::error_policy(), words, params, state);
    return ds1928::shm::classify(sample, r.bus_up, errors);
  };
  for (int i = 0; i < 5; ++i) REQUIRE(validity(s.step()) == ds1928::shm::AxisValidity::Valid);
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  REQUIRE(st != nullptr);

  sim::PowerlinkCnFaults not_ready;
  not_ready.pres_not_ready = true;
  s.cn->set_faults(not_ready);
  const uint64_t sent_before = s.cn->stats().pres_sent;
  for (int i = 0; i < 100; ++i) {
    const auto r = s.step();
    REQUIRE(r.bus_up);  // the CN answers and stays OPERATIONAL: only its data is not ready
    CHECK_FALSE(s.io[0].inputs_fresh);
    CHECK(validity(r) == ds1928::shm::AxisValidity::Stale);
  }
  CHECK(s.cn->stats().pres_sent - sent_before == 100);
  CHECK(s.cn->stats().pres_not_ready == 100);
  CHECK(st->pres_not_ready == 100);
  CHECK_FALSE(st->pres_ready);
  CHECK(st->boot == pl::CnBootState::kOperational);
  CHECK(st->resets == 0);
  CHECK(st->loss_of_pres.events == 0);

  s.cn->set_faults({});
  CHECK(validity(s.step()) == ds1928::shm::AxisValidity::Valid);
  CHECK(st->pres_ready);
}

TEST_CASE("The simulated CN asks for its own reset and the MN serves it") {
  Setup s;
  REQUIRE(s.run_until_operational(3000));
  s.cn->request_own_reset();
  bool left = false;
  for (int i = 0; i < 100 && !left; ++i) left = !s.step().bus_up;
  REQUIRE(left);
  CHECK(s.cn->stats().nmt_requests_sent == 1);
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  REQUIRE(st != nullptr);
  CHECK(st->nmt_requests == 1);
  CHECK(st->nmt_requests_refused == 0);
  CHECK(st->last_reset_reason == pl::MnError::kResetRequested);
  REQUIRE(s.run_until_operational(5000));
  CHECK(st->boots == 2);
  CHECK(st->resets == 1);
  CHECK(s.cn->stats().power_cycles == 0);
  CHECK(s.cn->stats().nmt_requests_sent == 1);  // asked once, not again after the reset
}

TEST_CASE(
    "A simulated CN power-cycled during the MN's NMTResetConfiguration wait gets its "
    "configuration again (0x1020 verified)") {
  constexpr uint32_t kDate = 0x3124;
  constexpr uint32_t kTime = 0x03735955;
  const auto u32 = [](uint32_t v) {
    return std::vector<uint8_t>{static_cast<uint8_t>(v), static_cast<uint8_t>(v >> 8),
                                static_cast<uint8_t>(v >> 16), static_cast<uint8_t>(v >> 24)};
  };
  Setup s({}, 15, [&](ds1928::PowerlinkNodeConfig& n) {
    n.object_writes = {{0x1020, 1, u32(kDate), true}, {0x1020, 2, u32(kTime), true}};
    n.expected_conf_date = kDate;
    n.expected_conf_time = kTime;
  });
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  REQUIRE(st != nullptr);
  // The node has taken the MN's NMTResetConfiguration (it went back to NOT_ACTIVE) and loses
  // power before it is identified again; nothing was stored with 0x1010, so it comes back with
  // its defaults.
  bool in_reset = false;
  for (int i = 0; i < 3000 && !in_reset; ++i) {
    (void)s.step();
    in_reset = st->configuration_resets == 1 && s.cn->stats().nmt_commands == 1;
  }
  REQUIRE(in_reset);
  REQUIRE(s.cn->nmt_state() == pl::NmtState::kNotActive);
  REQUIRE_FALSE(st->identified);  // the MN waits reset_wait_ms before it asks again
  REQUIRE(s.cn->communication_objects().configuration_date() == kDate);  // it had the download
  s.cn->power_cycle(g_now_ns);
  REQUIRE(s.run_until_operational(5000));
  CHECK(s.cn->stats().power_cycles == 1);
  CHECK(st->configuration_not_verified == 1);
  CHECK(st->configuration_resets == 2);
  CHECK(st->resets == 0);
  CHECK(s.cn->communication_objects().configuration_date() == kDate);
  CHECK(s.cn->communication_objects().configuration_time() == kTime);
}

namespace {
pl::PdoMapEntry map_entry(uint16_t index, uint8_t sub, unsigned byte_offset, unsigned bytes) {
  return {index, sub, static_cast<uint16_t>(byte_offset * 8), static_cast<uint16_t>(bytes * 8)};
}
// The objects a CDC writes for a mapping: sub 0 = 0 (disabled), the entries, sub 0 = count.
void write_mapping(ds1928::PowerlinkNodeConfig& n, uint16_t index,
                   const std::vector<pl::PdoMapEntry>& entries) {
  n.object_writes.push_back({index, 0, {0}, true});
  for (std::size_t i = 0; i < entries.size(); ++i) {
    std::vector<uint8_t> d(8);
    const uint64_t v = entries[i].to_u64();
    for (int b = 0; b < 8; ++b) d[b] = static_cast<uint8_t>(v >> (8 * b));
    n.object_writes.push_back({index, static_cast<uint8_t>(i + 1), d, true});
  }
  n.object_writes.push_back({index, 0, {static_cast<uint8_t>(entries.size())}, true});
}
}  // namespace

TEST_CASE("A CN mapped with PosCycle before PositionLW and gaps is decoded exactly") {
  // TPDO: PosCycle at 0, a gap, PositionLW before PositionHW, PosTime, ErrorInfo, InputSequence,
  // another gap, the Rx bytes; no SDCLifeCount. RPDO: AckErrorInfo first, a gap, OutputSequence,
  // the Tx bytes.
  std::vector<pl::PdoMapEntry> tpdo = {map_entry(0x2001, 4, 0, 1),  map_entry(0x2001, 2, 4, 4),
                                       map_entry(0x2001, 1, 8, 4),  map_entry(0x2001, 3, 12, 4),
                                       map_entry(0x2001, 6, 16, 1), map_entry(0x2001, 7, 17, 1)};
  for (uint8_t b = 0; b < 7; ++b) tpdo.push_back(map_entry(0x2001, 8 + b, 20 + b, 1));
  std::vector<pl::PdoMapEntry> rpdo = {map_entry(0x2101, 2, 0, 1), map_entry(0x2101, 1, 3, 1)};
  for (uint8_t b = 0; b < 7; ++b) rpdo.push_back(map_entry(0x2101, 3 + b, 4 + b, 1));
  Setup s({}, 15, [&](ds1928::PowerlinkNodeConfig& n) {
    write_mapping(n, 0x1A00, tpdo);
    write_mapping(n, 0x1600, rpdo);
  });
  REQUIRE(s.mn->managing_node().layout(1)->modules[0].by_fields);
  REQUIRE(s.run_until_operational(5000));
  REQUIRE(s.cn->image_by_mapping());  // took the mapping at NMTResetConfiguration
  CHECK(s.cn->stats().mappings_taken >= 1);
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  CHECK(st->pres_size == 27);
  CHECK(st->preq_size == 11);

  ds1928::AxisDecodeState state;
  const ds1928::AxisDecodeParams params;
  double first = 0, last = 0;
  int64_t first_t = 0, last_t = 0;
  for (int i = 0; i < 200; ++i) {
    s.io[0].outputs.output_sequence = static_cast<uint8_t>(i);
    s.io[0].outputs.ack_error_info = 0;
    const auto r = s.step();
    REQUIRE(r.bus_up);
    REQUIRE(s.io[0].inputs_fresh);
    // The registers are the bytes at their mapped offsets, as the CN put them on the wire.
    const auto pres = s.mn->managing_node().pres_payload(1);
    REQUIRE(pres.size() == 27);
    CHECK(s.io[0].inputs.pos_cycle == static_cast<int8_t>(pres[0]));
    CHECK(s.io[0].inputs.position_lw == pl::load_le32(pres.data() + 4));
    CHECK(s.io[0].inputs.position_hw == pl::load_le32(pres.data() + 8));
    CHECK(s.io[0].inputs.pos_time_us == pl::load_le32(pres.data() + 12));
    // ... and the PReq carries the outputs where the RPDO mapping puts them.
    REQUIRE(s.wire.last_preq.size() == 11);
    CHECK(s.wire.last_preq[3] == static_cast<uint8_t>(i));
    CHECK(s.wire.last_preq[0] == 0);
    auto sample = ds1928::decode_axis(s.io[0], params, r.net_time, state);
    REQUIRE(sample.fresh);
    REQUIRE(sample.error_info == 0);
    const double pos = static_cast<double>(sample.periods) + sample.fraction / 65536.0;
    if (i == 0) {
      first = pos;
      first_t = sample.pos_time_ns;
    }
    last = pos;
    last_t = sample.pos_time_ns;
  }
  // The simulator's motion, 100 periods/s: positions and NetTime stamps agree only when every
  // register came from its own bytes.
  const double dt = static_cast<double>(last_t - first_t) / 1e9;
  CHECK(dt > 0.15);
  CHECK(std::fabs((last - first) - 100.0 * dt) < 0.02);
}

TEST_CASE("The MN reads a CN's own rearranged mapping by SDO and decodes it exactly") {
  // No mapping written (layout auto): the CN's own 0x1A00/0x1600 are read in "configure".
  const auto style = GENERATE(sim::OwnMapping::kPosCycleFirst, sim::OwnMapping::kGap);
  CAPTURE(static_cast<int>(style));
  Setup s({}, 15, {}, [&](sim::PowerlinkCnConfig& c) { c.own_mapping = style; });
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  CHECK(st->image_source == pl::ImageSource::kPacked);  // until read
  REQUIRE(s.run_until_operational(5000));
  REQUIRE(s.cn->image_by_mapping());
  CHECK(st->image_source == pl::ImageSource::kReadMapping);
  const pl::NodeImageLayout* layout = s.mn->managing_node().layout(1);
  REQUIRE(layout->modules[0].by_fields);

  // What the CN serves, entry for entry, is what the MN bound from.
  const pl::NodeImageLayout packed =
      *pl::make_layout(std::vector<pl::ModuleSpec>{{1, 7, 7, {}, {}}});
  const sim::OwnPdoMapping own = sim::own_pdo_mapping(style, packed, pl::ObjectScheme{});
  const auto tpdo = s.mn->managing_node().mapped_objects(1, true);
  const auto rpdo = s.mn->managing_node().mapped_objects(1, false);
  REQUIRE(tpdo.size() == own.tpdo.size());
  REQUIRE(rpdo.size() == own.rpdo.size());
  for (std::size_t i = 0; i < tpdo.size(); ++i) CHECK(tpdo[i].to_u64() == own.tpdo[i].to_u64());
  for (std::size_t i = 0; i < rpdo.size(); ++i) CHECK(rpdo[i].to_u64() == own.rpdo[i].to_u64());
  auto offset_of = [&](uint8_t sub) {
    for (const pl::PdoMapEntry& e : own.tpdo)
      if (e.subindex == sub) return std::size_t{e.offset_bits} / 8;
    return std::size_t{0};
  };
  auto out_offset_of = [&](uint8_t sub) {
    for (const pl::PdoMapEntry& e : own.rpdo)
      if (e.subindex == sub) return std::size_t{e.offset_bits} / 8;
    return std::size_t{0};
  };
  if (style == sim::OwnMapping::kPosCycleFirst) CHECK(offset_of(4) < offset_of(2));
  if (style == sim::OwnMapping::kGap) CHECK(offset_of(2) == offset_of(1) + 5);

  ds1928::AxisDecodeState state;
  const ds1928::AxisDecodeParams params;
  double first = 0, last = 0;
  int64_t first_t = 0, last_t = 0;
  for (int i = 0; i < 200; ++i) {
    s.io[0].outputs.output_sequence = static_cast<uint8_t>(i);
    const auto r = s.step();
    REQUIRE(r.bus_up);
    REQUIRE(s.io[0].inputs_fresh);
    const auto pres = s.mn->managing_node().pres_payload(1);
    CHECK(s.io[0].inputs.position_hw == pl::load_le32(pres.data() + offset_of(1)));
    CHECK(s.io[0].inputs.position_lw == pl::load_le32(pres.data() + offset_of(2)));
    CHECK(s.io[0].inputs.pos_time_us == pl::load_le32(pres.data() + offset_of(3)));
    CHECK(s.io[0].inputs.pos_cycle == static_cast<int8_t>(pres[offset_of(4)]));
    CHECK(s.wire.last_preq[out_offset_of(1)] == static_cast<uint8_t>(i));
    auto sample = ds1928::decode_axis(s.io[0], params, r.net_time, state);
    REQUIRE(sample.fresh);
    REQUIRE(sample.error_info == 0);
    const double pos = static_cast<double>(sample.periods) + sample.fraction / 65536.0;
    if (i == 0) {
      first = pos;
      first_t = sample.pos_time_ns;
    }
    last = pos;
    last_t = sample.pos_time_ns;
  }
  // The simulator's motion, 100 periods/s: exact only when every register came from its bytes.
  const double dt = static_cast<double>(last_t - first_t) / 1e9;
  CHECK(dt > 0.15);
  CHECK(std::fabs((last - first) - 100.0 * dt) < 0.02);
}

TEST_CASE(
    "A CN that maps no TPDO keeps the packed image, or with layout mapping is refused by name") {
  SECTION("auto: packed") {
    Setup s;
    REQUIRE(s.run_until_operational(5000));
    const pl::CnStatus* st = s.mn->managing_node().node(1);
    CHECK(st->image_source == pl::ImageSource::kPacked);
    CHECK_FALSE(s.mn->managing_node().layout(1)->modules[0].by_fields);
    s.step();
    CHECK(s.io[0].inputs_fresh);
  }
  SECTION("mapping: refused, the node runs without feeding its axis") {
    Setup s({}, 15,
            [](ds1928::PowerlinkNodeConfig& n) { n.layout = ds1928::ImageLayout::kMapping; });
    REQUIRE(s.run_until_operational(5000));
    const pl::CnStatus* st = s.mn->managing_node().node(1);
    CHECK(st->image_source == pl::ImageSource::kRefused);
    CHECK(st->image_error == pl::MnError::kPdoRegisterNotMapped);
    CHECK_THAT(std::string(st->image_refusal.data()), Catch::Contains("maps no TPDO"));
    for (int i = 0; i < 20; ++i) {
      s.step();
      CHECK_FALSE(s.io[0].inputs_fresh);
    }
  }
}

TEST_CASE("A CN's own mapping that lacks a configured axis' register refuses that axis only") {
  // The CN hosts one module (slot 1); the configuration has an axis in slot 2 as well.
  Setup s({}, 15, {}, [](sim::PowerlinkCnConfig& c) { c.own_mapping = sim::OwnMapping::kGap; },
          {1, 2});
  REQUIRE(s.run_until_operational(5000));
  const pl::CnStatus* st = s.mn->managing_node().node(1);
  CHECK(st->image_source == pl::ImageSource::kReadMapping);
  CHECK(st->image_error == pl::MnError::kPdoRegisterNotMapped);
  CHECK(std::string(st->image_refusal.data()) == "slot 2: PositionHW (0x2002/1) is not mapped");
  REQUIRE(s.mn->managing_node().layout(1)->count == 1);
  CHECK(s.mn->managing_node().layout(1)->modules[0].slot == 1);
  for (int i = 0; i < 20; ++i) {
    s.step();
    CHECK(s.io[0].inputs_fresh);  // slot 1 runs from the mapping
    CHECK_FALSE(s.io[1].inputs_fresh);
  }
}
