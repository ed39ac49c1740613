// The CAN-I/O node lifecycle in virtual time (stepped rig: fake clock, the timed virtual bus,
// simulated nodes that are strict CANopen nodes): NMT Start, a node that resets itself with the
// bus up and during a bus-off, the heartbeat consumer, EMCY, Start repeated with back-off, every
// SDO abort at every configuration step, "size not indicated" uploads, bus errors kept out of the
// cycle, restart-ms 0, and a stalled acquisition through the axis decoding. Each failed before the
// change (the comments say how).
#include <catch2/catch.hpp>
#include <cstdio>
#include <map>
#include <set>

#include "can/can_error_frame.hpp"
#include "canio/canio_options.hpp"
#include "canio/canopen_nmt.hpp"
#include "core/axis_sample.hpp"
#include "core/sdo_abort.hpp"
#include "rig.hpp"
#include "x20ds1928/object_dictionary.hpp"

using namespace ds1928;
using namespace ds1928::test;

namespace {

constexpr int64_t kMs = 1'000'000;

uint64_t position_of(const ModuleInputs& in) {
  return (uint64_t{in.position_hw} << 32) | in.position_lw;
}

// Runs stepped cycles and checks every published sample against what the node sent for that
// very SYNC (cycle = SYNC time on the fake clock).
struct Run {
  explicit Run(Rig& r) : rig(r) {
    rig.nodes[0]->on_inputs = [this](std::size_t, int64_t t, const ModuleInputs& in) {
      sent[static_cast<uint64_t>((t - Rig::kT0) / period_ns())] = in;
    };
  }
  [[nodiscard]] int64_t period_ns() const { return int64_t{rig.config.cycle.period_us} * 1000; }
  // One cycle; counts fresh samples and wrong ones.
  void step() {
    (void)rig.cycle(c);
    if (rig.io[0].inputs_fresh) {
      ++fresh;
      const auto it = sent.find(c);
      if (it == sent.end() || position_of(it->second) != position_of(rig.io[0].inputs) ||
          it->second.pos_cycle != rig.io[0].inputs.pos_cycle)
        ++wrong;
    }
    sent.erase(c);
    ++c;
  }
  template <class Done>
  bool until(Done done, uint64_t max_cycles = 20000) {
    for (uint64_t i = 0; i < max_cycles; ++i) {
      step();
      if (done()) return true;
    }
    return false;
  }
  Rig& rig;
  uint64_t c = 0;
  uint64_t fresh = 0;
  uint64_t wrong = 0;
  std::map<uint64_t, ModuleInputs> sent;
};

std::vector<canio::CanioNodeEvent> events(canio::CanioBus& bus) {
  std::vector<canio::CanioNodeEvent> out;
  canio::CanioNodeEvent e;
  while (bus.poll_event(e)) out.push_back(e);
  return out;
}

bool has_event(const std::vector<canio::CanioNodeEvent>& v, canio::CanioNodeEventKind k) {
  for (const auto& e : v)
    if (e.kind == k) return true;
  return false;
}

}  // namespace

TEST_CASE("CAN-I/O NMT: a node that waits pre-operational for NMT Start delivers exact positions",
          "[canio][nmt]") {
  // Before: nothing sent NMT; the strict node never left pre-operational, no sample ever came.
  Rig rig(canio_config(1), true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  CHECK(rig.nodes[0]->nmt_state() == canio::NmtState::PreOperational);
  REQUIRE(run.until([&] { return run.fresh >= 500; }));
  CHECK(run.wrong == 0);
  CHECK(rig.nodes[0]->nmt_state() == canio::NmtState::Operational);
  CHECK(rig.canio->node_counters(0).nmt_starts.load() == 1);
  CHECK(rig.canio->node_counters(0).start_retries.load() == 0);
  CHECK(rig.nodes[0]->counters().ignored_not_operational > 0);  // SYNCs before the Start
  // Stop: the nodes are told to leave OPERATIONAL (Enter Pre-Operational).
  rig.canio->stop();
  for (int i = 0; i < 5; ++i) (void)rig.advance(fake_now() + 1 * kMs);
  CHECK(rig.nodes[0]->nmt_state() == canio::NmtState::PreOperational);
}

TEST_CASE("CAN-I/O NMT: canio.nmt none sends no NMT (a bus controller that starts by itself)",
          "[canio][nmt]") {
  DaemonConfig config = canio_config(1);
  config.canio.nmt = CanNmt::None;
  Rig rig(config, true, false, [](sim::CanioNodeConfig& nc) { nc.self_start = true; });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh >= 50; }));
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_counters(0).nmt_starts.load() == 0);
  CHECK(rig.nodes[0]->counters().nmt_commands == 0);
}

TEST_CASE("CAN-I/O NMT: a node that misses its Start is started again with back-off, reported",
          "[canio][nmt]") {
  // Before: a configured node that stayed silent was never addressed again.
  Rig rig(canio_config(1), true, false,
          [](sim::CanioNodeConfig& nc) { nc.faults.ignore_nmt_starts = 3; });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until(
      [&] { return rig.canio->axis_counters(0).state.load() == canio::CanioAxisState::Starting; }));
  CHECK_THAT(rig.canio->axis_reason(0), Catch::Contains("NMT Start"));
  REQUIRE(run.until([&] { return run.fresh > 0; }));
  CHECK(run.wrong == 0);
  const auto& nc = rig.canio->node_counters(0);
  CHECK(nc.nmt_starts.load() == 4);
  CHECK(nc.start_retries.load() == 3);
  const auto ev = events(*rig.canio);
  std::vector<uint32_t> backoff;
  for (const auto& e : ev)
    if (e.kind == canio::CanioNodeEventKind::StartRetry) backoff.push_back(e.detail);
  CHECK(backoff == std::vector<uint32_t>{100, 200, 400});  // bounded, doubling
}

TEST_CASE(
    "CAN-I/O boot-up: a node that resets itself with the bus up is configured and started "
    "again, nothing Valid in between",
    "[canio][nmt][bootup]") {
  // Before: the boot-up was not listened to; after the reset the node waited pre-operational
  // for ever (or, self-starting, was published with EnDat disabled).
  Rig rig(canio_config(1), true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  const auto& ac = rig.canio->axis_counters(0);
  REQUIRE(run.until([&] { return run.fresh >= 100; }));
  REQUIRE(ac.configurations.load() == 1);
  (void)events(*rig.canio);

  rig.nodes[0]->request_reset();  // brown-out: the modules' settings are lost
  const uint64_t fresh_before = run.fresh;
  REQUIRE(run.until([&] { return ac.configurations.load() == 2; }));
  // Between the reset and the new configuration: no fresh sample, the axis down.
  CHECK(run.fresh == fresh_before);
  CHECK(rig.canio->node_counters(0).boot_ups.load() == 1);
  CHECK(has_event(events(*rig.canio), canio::CanioNodeEventKind::BootUp));
  REQUIRE(run.until([&] { return run.fresh >= fresh_before + 100; }));
  CHECK(run.wrong == 0);
  CHECK(rig.canio->node_counters(0).nmt_starts.load() == 2);
  uint32_t mode = 0;
  REQUIRE_FALSE(rig.nodes[0]->module(0).read_register(reg::kEnDatMode, 1, mode));
  CHECK((mode & 1) == 1);  // EnDat enabled again
}

TEST_CASE("CAN-I/O boot-up: a node that resets during a bus-off is configured again after it",
          "[canio][nmt][bootup][busoff]") {
  // Before: after the restart the node (its boot-up lost in the bus-off) waited pre-operational
  // and its axis stayed silent; a self-starting one was published with EnDat disabled.
  Rig rig(canio_config(1), true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  const auto& ac = rig.canio->axis_counters(0);
  REQUIRE(run.until([&] { return run.fresh >= 100; }));
  REQUIRE(ac.configurations.load() == 1);

  canio::CanErrorEvent off;
  off.bus_off = true;
  REQUIRE(rig.node_ports[0]->broadcast_error(off));  // the daemon's controller goes bus-off
  run.step();
  CHECK(rig.canio->state() == BusState::Error);
  rig.nodes[0]->request_reset();
  const uint64_t fresh_before = run.fresh;
  REQUIRE(run.until([&] { return rig.canio->counters().bus_restarts.load() == 1; }));
  CHECK(rig.canio->node_counters(0).boot_ups.load() == 0);  // the boot-up went unheard
  REQUIRE(run.until([&] { return ac.configurations.load() == 2; }));
  CHECK(run.fresh == fresh_before);
  REQUIRE(run.until([&] { return run.fresh >= fresh_before + 100; }));
  CHECK(run.wrong == 0);
  const auto ev = events(*rig.canio);
  CHECK(has_event(ev, canio::CanioNodeEventKind::BusOff));
  CHECK(has_event(ev, canio::CanioNodeEventKind::BusRestarted));
}

TEST_CASE(
    "CAN-I/O heartbeat: 0x1017 written, a missed heartbeat takes the axes down within the "
    "consumer timeout",
    "[canio][nmt][heartbeat]") {
  DaemonConfig config = canio_config(1);
  config.canio.nodes.push_back({1, 50, 0, {}});  // consumer timeout 75 ms
  Rig rig(config, true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh >= 100; }));
  CHECK(rig.nodes[0]->heartbeat_ms() == 50);
  const auto& nc = rig.canio->node_counters(0);
  CHECK(nc.heartbeat_watched.load());
  CHECK(nc.heartbeats.load() >= 2);
  CHECK(nc.heartbeat_misses.load() == 0);
  CHECK(nc.start_retries.load() == 0);  // a heartbeat sent before the Start took is no reason
  CHECK(nc.nmt_state.load() == static_cast<uint8_t>(canio::NmtState::Operational));

  rig.nodes[0]->set_silent(true);
  const int64_t silent_at = fake_now();
  REQUIRE(run.until([&] { return !rig.io[0].axis_up; }, 1000));
  const int64_t down_after = fake_now() - silent_at;
  INFO("down after " << down_after / kMs << " ms");
  std::printf(
      "canio heartbeat: producer 50 ms, consumer 75 ms: axis down %.1f ms after the node "
      "fell silent\n",
      static_cast<double>(down_after) / 1e6);
  CHECK(down_after <= 75 * kMs + 2 * run.period_ns());
  CHECK(down_after >= 50 * kMs);  // not before a heartbeat could have been missed
  CHECK(nc.heartbeat_misses.load() == 1);
  CHECK(has_event(events(*rig.canio), canio::CanioNodeEventKind::HeartbeatMissed));
  CHECK(nc.nmt_state.load() == 0xFF);  // its state unknown since (status, the module state)

  rig.nodes[0]->set_silent(false);
  const uint64_t fresh_before = run.fresh;
  REQUIRE(run.until([&] { return run.fresh >= fresh_before + 50; }));
  CHECK(run.wrong == 0);
  CHECK(nc.heartbeat_misses.load() == 1);
  CHECK(nc.nmt_state.load() == static_cast<uint8_t>(canio::NmtState::Operational));
}

TEST_CASE("CAN-I/O EMCY: decoded, counted, queued as an event, the cycle goes on",
          "[canio][nmt][emcy]") {
  Rig rig(canio_config(1), true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh >= 10; }));
  (void)events(*rig.canio);
  rig.nodes[0]->request_emcy(0x7305, 0x81, {1, 2, 3, 4, 5});
  const uint64_t fresh_before = run.fresh;
  for (int i = 0; i < 20; ++i) run.step();
  CHECK(run.fresh == fresh_before + 20);
  const auto& nc = rig.canio->node_counters(0);
  CHECK(nc.emcys.load() == 1);
  CHECK((nc.last_emcy.load() & 0xFFFFFF) == 0x817305);
  bool seen = false;
  for (const auto& e : events(*rig.canio))
    if (e.kind == canio::CanioNodeEventKind::Emcy) {
      seen = true;
      CHECK(e.node == 1);
      CHECK(e.emcy.error_code == 0x7305);
      CHECK(e.emcy.error_register == 0x81);
      CHECK(e.emcy.vendor == std::array<uint8_t, 5>{1, 2, 3, 4, 5});
    }
  CHECK(seen);
}

TEST_CASE(
    "CAN-I/O configuration: every abort code at every step ends configured, "
    "unconfigurable or retried, never silent",
    "[canio][sdo][abort]") {
  // Before: a write abort, or a read-back abort other than write-only, ended the attempt before
  // EnDatMode was written; after three the axis went up "UNVERIFIED" with EnDat off and stayed
  // awaiting_pos_cycle for ever.
  const auto writes = startup_writes(ModuleSettings{});
  std::vector<uint16_t> regs;
  for (const auto& w : writes) regs.push_back(w.reg);
  regs.push_back(reg::kEnDatAck);  // the Rescan
  const std::vector<uint32_t> codes{sdo_abort::kUnsupportedAccess, sdo_abort::kWriteOnly,
                                    sdo_abort::kNoObject,          sdo_abort::kOutOfRange,
                                    sdo_abort::kGeneral,           sdo_abort::kDeviceState};
  int configured = 0, unconfigurable = 0;
  for (const uint16_t reg : regs)
    for (const uint32_t code : codes)
      for (const bool on_write : {true, false}) {
        if (reg == reg::kEnDatAck && !on_write) continue;  // a command: never read back
        DYNAMIC_SECTION("register " << reg << " abort 0x" << std::hex << code
                                    << (on_write ? " on write" : " on read-back")) {
          Rig rig(canio_config(1), true, false, [&](sim::CanioNodeConfig& nc) {
            nc.faults.config_write_only = false;
            nc.faults.abort_register = reg;
            nc.faults.abort_code = code;
            nc.faults.abort_on_write = on_write;
            nc.faults.abort_on_read = !on_write;
          });
          REQUIRE_FALSE(rig.canio->start());
          Run run(rig);
          const auto& ac = rig.canio->axis_counters(0);
          // 3 s of virtual time: configuration, Start, PosCycle gate, or the first retries.
          (void)run.until([&] { return run.fresh >= 20; }, 1500);
          const auto state = ac.state.load();
          INFO("state " << canio::to_string(state) << ", reason " << rig.canio->axis_reason(0)
                        << ", last error " << rig.canio->axis_last_error(0));
          CHECK(run.wrong == 0);
          if (run.fresh >= 20) {
            ++configured;
            CHECK(ac.configured.load());
            // Whatever was refused is named (a write) or counted (a read-back).
            if (on_write)
              CHECK_THAT(rig.canio->axis_last_error(0), Catch::Contains("refused"));
            else
              CHECK(ac.unverified.load() >= 1);
          } else {
            ++unconfigurable;
            // EnDatMode or the Rescan refused: the only registers positions depend on.
            CHECK(on_write);
            CHECK((reg == reg::kEnDatMode || reg == reg::kEnDatAck));
            CHECK(state == canio::CanioAxisState::Unconfigurable);
            CHECK_THAT(rig.canio->axis_reason(0),
                       Catch::StartsWith("unconfigurable: " + std::to_string(reg)) &&
                           Catch::Contains(sdo_abort_name(code).data()));
            // Retried with back-off: more than one attempt, fewer than one per 500 ms.
            CHECK(ac.sdo_errors.load() >= 2);
            CHECK(ac.sdo_errors.load() <= 4);
          }
        }
      }
}

TEST_CASE(
    "CAN-I/O SDO: expedited uploads with \"size not indicated\" are taken by the register's "
    "size",
    "[canio][sdo]") {
  // Before: such an answer was taken as 4 bytes: every read-back of a 1- or 2-byte register
  // "differed in size", and the axis went up unverified after three attempts.
  Rig rig(canio_config(1), true, false, [](sim::CanioNodeConfig& nc) {
    nc.faults.config_write_only = false;
    nc.faults.upload_size_not_indicated = true;
  });
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  const auto& ac = rig.canio->axis_counters(0);
  REQUIRE(run.until([&] { return run.fresh >= 10; }));
  CHECK(ac.configurations.load() == 1);
  CHECK(ac.unverified.load() == 0);
  CHECK(rig.canio->axis_last_error(0).empty());
  REQUIRE(rig.canio->submit({5, 0, reg::kEnDatMode, 1, false, 0}));
  RegisterResult r;
  REQUIRE(run.until([&] { return rig.canio->poll(r); }));
  CHECK_FALSE(r.error);
  CHECK(r.value == ModuleSettings{}.endat_mode());
}

TEST_CASE("CAN-I/O: bus-error frames never reach the cycle", "[canio][bus][errors]") {
  // Before: the error mask subscribed protocol violations, and the kernel reports every bus error
  // as CAN_ERR_PROT | CAN_ERR_BUSERROR: each one reached the cycle thread.
  Rig rig(canio_config(1), true, true);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh >= 5; }));
  canio::CanErrorEvent be;
  be.bus_error = true;
  be.protocol = true;
  be.protocol_type = canio::err_prot::kStuff;
  // The port delivers them as a kernel would: only when a class bit is subscribed.
  for (int i = 0; i < 10; ++i) REQUIRE(rig.driver_port->inject_error(be));
  const uint64_t fresh_before = run.fresh;
  for (int i = 0; i < 10; ++i) run.step();
  CHECK(run.fresh == fresh_before + 10);
  CHECK(rig.canio->counters().error_frames.load() == 0);
  CHECK(rig.driver_port->state() == canio::CanState::ErrorActive);
}

TEST_CASE("CAN-I/O: restart-ms 0 is refused at start with the command that fixes it",
          "[canio][bus][errors]") {
  // Before: accepted silently; the first bus-off was then permanent.
  for (const bool allow : {false, true}) {
    DaemonConfig config = canio_config(1);
    config.canio.allow_manual_restart = allow;
    auto bus = canio::VirtualCanBus::create_local();
    canio::VirtualPortOptions po;
    po.name = "can7";
    po.restart_ms = 0;
    auto cycle = bus->open_port(po);
    auto sdo = bus->open_port(po);
    REQUIRE(cycle);
    REQUIRE(sdo);
    canio::CanioBus driver(
        canio::make_canio_options(config.canio, config.axes, config.cycle.period_us),
        std::move(cycle.value()), std::move(sdo.value()));
    const auto ec = driver.start();
    if (allow) {
      CHECK_FALSE(ec);
    } else {
      CHECK(ec);
      CHECK_THAT(driver.start_error(), Catch::Contains("restart-ms 0") &&
                                           Catch::Contains("ip link set can7 type can bitrate "
                                                           "500000 restart-ms 100") &&
                                           Catch::Contains("allow_manual_restart"));
    }
  }
}

TEST_CASE(
    "CAN-I/O stall: 100 repeated samples are never new, keep their first stamp, and go "
    "stale after the limit",
    "[canio][stall]") {
  // Before: every repeat was published Valid with a new receive stamp (only NEW_POSITION was
  // cleared): a frozen module looked alive.
  Rig rig(canio_config(1), true, true);
  REQUIRE_FALSE(rig.canio->start());
  AxisDecodeParams params;
  params.has_pos_time = false;  // function model 254
  params.stall_limit = stall_limit_cycles(0, 2, rig.config.cycle.period_us);
  REQUIRE(params.stall_limit == 2);  // 2 × 400 µs over 2 ms, + 1
  AxisDecodeState state;
  uint64_t c = 0;
  auto cycle = [&] {
    (void)rig.cycle(c++);
    return decode_axis(rig.io[0], params, NetTimeRef{}, state);
  };
  for (int i = 0; i < 20; ++i) REQUIRE(cycle().new_position);
  rig.nodes[0]->set_stalled(true);
  // The first answer after the stall repeats the last position: the stamp of its first arrival.
  const AxisSample last = cycle();
  (void)last;
  int64_t first_stamp = 0;
  int new_flags = 0, stale = 0, newer_stamp = 0, fresh_repeats = 0;
  for (int i = 0; i < 100; ++i) {
    const AxisSample s = cycle();
    REQUIRE(rig.io[0].inputs_fresh);  // the driver saw a whole sample
    if (s.new_position) ++new_flags;
    if (!s.fresh) {
      ++stale;
      CHECK(s.stalled);
      continue;
    }
    ++fresh_repeats;
    if (first_stamp == 0) first_stamp = s.pos_time_ns;
    if (s.pos_time_ns != first_stamp) ++newer_stamp;
  }
  CHECK(new_flags == 0);
  CHECK(newer_stamp == 0);
  CHECK(fresh_repeats <= static_cast<int>(params.stall_limit));
  CHECK(stale >= 100 - static_cast<int>(params.stall_limit));
  CHECK(rig.nodes[0]->counters().stalled_answers >= 100);
  rig.nodes[0]->set_stalled(false);
  const AxisSample back = cycle();
  CHECK(back.fresh);
  CHECK(back.new_position);
  CHECK(back.pos_time_ns > first_stamp);
}

TEST_CASE("Stall rule under POWERLINK: a PosTime that does not move goes stale after the limit",
          "[core][stall]") {
  // The same rule where the module stamps its positions (function model 0): a PRes that repeats
  // PosCycle and PosTime carries no new position.
  AxisDecodeParams params;
  params.has_pos_time = true;
  params.stall_limit = 3;
  AxisDecodeState state;
  NetTimeRef ref{1'000'000, 5'000'000'000, true};
  AxisIo io;
  io.inputs_fresh = true;
  io.inputs.pos_cycle = 7;
  io.inputs.pos_time_us = 999'000;
  AxisSample s = decode_axis(io, params, ref, state);
  CHECK(s.new_position);
  const int64_t stamp = s.pos_time_ns;
  for (int i = 1; i <= 10; ++i) {
    ref.net_time_us += 2000;
    ref.monotonic_ns += 2'000'000;
    s = decode_axis(io, params, ref, state);
    CHECK_FALSE(s.new_position);
    CHECK(s.pos_time_ns == stamp);
    CHECK(s.fresh == (i <= 3));
    CHECK(s.stalled == (i > 3));
  }
  io.inputs.pos_cycle = 8;
  io.inputs.pos_time_us = 1'019'000;
  s = decode_axis(io, params, ref, state);
  CHECK(s.fresh);
  CHECK(s.new_position);
  // PosTime moved with the same PosCycle (it wrapped onto itself): a new position.
  io.inputs.pos_time_us = 1'021'000;
  s = decode_axis(io, params, ref, state);
  CHECK(s.new_position);
}

TEST_CASE("CAN-I/O NMT: a node put pre-operational by another master is started again",
          "[canio][nmt][heartbeat]") {
  // A configuration tool on the bus sends Enter Pre-Operational: the node keeps its settings but
  // sends no process data. Its heartbeat says so; the daemon starts it again (with back-off).
  DaemonConfig config = canio_config(1);
  config.canio.nodes.push_back({1, 20, 0, {}});
  Rig rig(config, true, false);
  REQUIRE_FALSE(rig.canio->start());
  Run run(rig);
  REQUIRE(run.until([&] { return run.fresh >= 100; }));
  const auto& nc = rig.canio->node_counters(0);
  REQUIRE(nc.start_retries.load() == 0);
  auto tool = rig.open_port("tool");
  auto preop = canio::build_nmt(canio::NmtCommand::EnterPreOperational, 1);
  REQUIRE(preop);
  REQUIRE(tool->send(*preop).sent());
  REQUIRE(
      run.until([&] { return rig.nodes[0]->nmt_state() == canio::NmtState::PreOperational; }, 10));
  const uint64_t fresh_before = run.fresh;
  REQUIRE(run.until([&] { return run.fresh >= fresh_before + 50; }));
  CHECK(run.wrong == 0);
  CHECK(nc.start_retries.load() >= 1);
  CHECK(rig.canio->axis_counters(0).configurations.load() == 1);  // settings kept: no rewrite
  CHECK(has_event(events(*rig.canio), canio::CanioNodeEventKind::StartRetry));
}
