// The CAN-I/O driver's register access as a state machine stepped by the cycle, in virtual time:
// the stepped rig (fake clock, simulated nodes served between the cycles on the timed virtual
// bus), so every timeout, retry and pacing interval is the driver's clock and every run is the
// same run. Configuration at start, pacing, a transfer that times out, an abort from the node, a
// request queued while one is in flight, the request and result queues at their depth, requests
// that wait for their axis' configuration.
#include <catch2/catch.hpp>
#include <vector>

#include "canio/sdo_expedited.hpp"
#include "core/axis_info.hpp"
#include "endat/names.hpp"
#include "rig.hpp"
#include "x20ds1928/info_channels.hpp"

using namespace ds1928;
using namespace ds1928::test;

namespace {

constexpr uint16_t kManufacturerWord = 4356;  // an EnDat parameter word, 2 bytes
constexpr int64_t kMs = 1'000'000;

// Cycles in virtual time until `done` (checked after each cycle) or `max_cycles`.
struct Steps {
  Rig& rig;
  uint64_t cycle = 0;
  template <class Done>
  bool until(Done done, uint64_t max_cycles = 20000) {
    for (uint64_t i = 0; i < max_cycles; ++i) {
      (void)rig.cycle(cycle++);
      if (done()) return true;
    }
    return false;
  }
};

// A rig whose modules are configured over SDO (not assumed), every axis Operational.
struct ConfiguredRig {
  explicit ConfiguredRig(int nodes = 1, Rig::NodeTweak tweak = {})
      : rig(canio_config(nodes), true, false, std::move(tweak)) {
    REQUIRE_FALSE(rig.canio->start());
  }
  Rig rig;
  Steps steps{rig};
};

}  // namespace

TEST_CASE("CAN-I/O SDO: configuration at start, paced to one transfer per sdo_interval_us",
          "[canio][sdo][engine]") {
  ConfiguredRig r;
  const auto& ac = r.rig.canio->axis_counters(0);
  const int64_t interval = int64_t{r.rig.config.canio.sdo_interval_us} * 1000;
  const int64_t period = int64_t{r.rig.config.cycle.period_us} * 1000;
  std::vector<int64_t> started;  // fake time of each transfer's start
  uint64_t seen = 0;
  REQUIRE(r.steps.until([&] {
    const uint64_t now = ac.sdo_transfers.load();
    REQUIRE(now - seen <= 1);  // at most one transfer a cycle
    if (now != seen) started.push_back(fake_now());
    seen = now;
    return r.rig.io[0].inputs_fresh;
  }));
  CHECK(ac.configurations.load() == 1);
  CHECK(ac.rescans.load() == 1);
  CHECK(ac.sdo_errors.load() == 0);
  CHECK(r.rig.canio->axis_last_error(0).empty());
  // Every start-up write read back, then the Rescan.
  REQUIRE(started.size() == 2 * kStartupWriteCount + 1);
  // On average never more than one transfer per interval (one period of slack).
  const int64_t span = started.back() - started.front();
  CHECK(span >= static_cast<int64_t>(started.size() - 1) * interval - period);
  // The node saw exactly these requests.
  CHECK(r.rig.nodes[0]->counters().sdo_requests == started.size());
}

TEST_CASE("CAN-I/O SDO: a request without answer times out on the driver's clock",
          "[canio][sdo][engine]") {
  ConfiguredRig r;
  const auto& ac = r.rig.canio->axis_counters(0);
  REQUIRE(r.steps.until([&] { return r.rig.io[0].inputs_fresh; }));
  const uint64_t errors = ac.sdo_errors.load();
  r.rig.nodes[0]->drop_sdo_requests(1);
  REQUIRE(r.rig.canio->submit({1, 0, kManufacturerWord, 2, false, 0}));
  RegisterResult res;
  int64_t sent_at = 0;
  const uint64_t transfers = ac.sdo_transfers.load();
  REQUIRE(r.steps.until([&] {
    if (sent_at == 0 && ac.sdo_transfers.load() > transfers) sent_at = fake_now();
    return r.rig.canio->poll(res);
  }));
  CHECK(res.tag == 1);
  CHECK(res.error == canio::CanioBusError::kSdoTimeout);
  INFO(res.error.message());
  const int64_t timeout = int64_t{r.rig.config.canio.sdo_timeout_ms} * kMs;
  const int64_t period = int64_t{r.rig.config.cycle.period_us} * 1000;
  // Timed out at the first cycle past sdo_timeout_ms, not before.
  CHECK(fake_now() - sent_at >= timeout);
  CHECK(fake_now() - sent_at <= timeout + 2 * period);
  CHECK(ac.sdo_errors.load() == errors + 1);
  // The node answers again: the next request is served.
  REQUIRE(r.rig.canio->submit({2, 0, kManufacturerWord, 2, false, 0}));
  REQUIRE(r.steps.until([&] { return r.rig.canio->poll(res); }));
  CHECK(res.tag == 2);
  CHECK_FALSE(res.error);
  // Positions went on meanwhile: the cycle never waited for the SDO.
  CHECK(r.rig.io[0].inputs_fresh);
}

TEST_CASE("CAN-I/O SDO: an abort from the node is the request's error, counted",
          "[canio][sdo][engine]") {
  ConfiguredRig r;
  const auto& ac = r.rig.canio->axis_counters(0);
  REQUIRE(r.steps.until([&] { return r.rig.io[0].inputs_fresh; }));
  const uint64_t errors = ac.sdo_errors.load();
  // Out of range for the module: refused with a CiA 301 abort.
  REQUIRE(r.rig.canio->submit({5, 0, reg::kForward, 1, true, 9}));
  RegisterResult res;
  REQUIRE(r.steps.until([&] { return r.rig.canio->poll(res); }));
  CHECK(res.tag == 5);
  REQUIRE(res.error);
  CHECK(res.error.category() == ds1928::sdo_abort_category());
  CHECK_THAT(res.error.message(), Catch::Contains("SDO abort 0x"));
  CHECK(ac.sdo_errors.load() == errors + 1);
  // A register without SDO object ends without a transfer, naming why.
  const uint64_t transfers = ac.sdo_transfers.load();
  REQUIRE(r.rig.canio->submit({6, 0, 9999, 1, false, 0}));
  REQUIRE(r.steps.until([&] { return r.rig.canio->poll(res); }));
  CHECK(res.error == canio::CanioBusError::kNoSdoObject);
  CHECK(ac.sdo_transfers.load() == transfers);
  // An axis that does not exist.
  REQUIRE(r.rig.canio->submit({7, 3, kManufacturerWord, 2, false, 0}));
  REQUIRE(r.steps.until([&] { return r.rig.canio->poll(res); }));
  CHECK(res.tag == 7);
  CHECK(res.error == canio::CanioBusError::kNoSuchAxis);
}

TEST_CASE("CAN-I/O SDO: a request queued while one is in flight waits for it",
          "[canio][sdo][engine]") {
  ConfiguredRig r;
  const auto& ac = r.rig.canio->axis_counters(0);
  REQUIRE(r.steps.until([&] { return r.rig.io[0].inputs_fresh; }));
  const uint64_t transfers = ac.sdo_transfers.load();
  // The write's request is lost: it stays in flight for sdo_timeout_ms.
  r.rig.nodes[0]->drop_sdo_requests(1);
  REQUIRE(r.rig.canio->submit({1, 0, reg::kForward, 1, true, 1}));
  REQUIRE(r.rig.canio->submit({2, 0, kManufacturerWord, 2, false, 0}));
  std::vector<RegisterResult> results;
  auto collect = [&] {
    RegisterResult res;
    while (r.rig.canio->poll(res)) results.push_back(res);
  };
  REQUIRE(r.steps.until([&] {
    collect();
    // Until the write has ended, the read is not started.
    if (results.empty()) CHECK(ac.sdo_transfers.load() - transfers <= 1);
    return !results.empty();
  }));
  CHECK(results[0].tag == 1);
  CHECK(results[0].error == canio::CanioBusError::kSdoTimeout);
  REQUIRE(r.steps.until([&] {
    collect();
    return results.size() == 2;
  }));
  CHECK(results[1].tag == 2);
  CHECK_FALSE(results[1].error);
  CHECK(ac.sdo_transfers.load() == transfers + 2);  // the write (no read-back: it failed), the read
}

TEST_CASE("CAN-I/O SDO: request and result queues at their depth lose nothing",
          "[canio][sdo][engine]") {
  ConfiguredRig r;
  const auto& ac = r.rig.canio->axis_counters(0);
  REQUIRE(r.steps.until([&] { return r.rig.io[0].inputs_fresh; }));
  const RegisterRequest read{0, 0, kManufacturerWord, 2, false, 0};
  auto request = [&](uint32_t tag) {
    RegisterRequest q = read;
    q.tag = tag;
    return q;
  };
  // The request queue takes kSdoQueueDepth, then refuses (the caller tries again later).
  uint32_t tag = 0;
  for (std::size_t i = 0; i < canio::kSdoQueueDepth; ++i)
    REQUIRE(r.rig.canio->submit(request(++tag)));
  CHECK_FALSE(r.rig.canio->submit(request(tag + 1)));
  // Nobody polls: the results fill their queue, then one result is held and no further transfer
  // starts; the requests submitted meanwhile wait in theirs.
  const uint32_t total = 2 * canio::kSdoQueueDepth;
  REQUIRE(r.steps.until([&] {
    while (tag < total && r.rig.canio->submit(request(tag + 1))) ++tag;
    return tag == total;
  }));
  REQUIRE(r.steps.until([] { return false; }, 1000) == false);  // 2 s: all it can do
  const uint64_t held = ac.sdo_transfers.load();
  REQUIRE(r.steps.until([] { return false; }, 1000) == false);
  CHECK(ac.sdo_transfers.load() == held);
  // Polled: every result, in order.
  std::vector<uint32_t> tags;
  REQUIRE(r.steps.until([&] {
    RegisterResult res;
    while (r.rig.canio->poll(res)) {
      CHECK_FALSE(res.error);
      tags.push_back(res.tag);
    }
    return tags.size() == total;
  }));
  for (uint32_t i = 0; i < tags.size(); ++i) CHECK(tags[i] == i + 1);
}

TEST_CASE("CAN-I/O SDO: a request for an axis being configured waits for it, at most 2 s",
          "[canio][sdo][engine]") {
  // Node 2 has no SDO server: its module is never configured.
  ConfiguredRig r(2, [](sim::CanioNodeConfig& nc) {
    if (nc.node == 2) nc.faults.answer_sdo = false;
  });
  REQUIRE(r.rig.canio->submit({1, 1, kManufacturerWord, 2, false, 0}));  // axis 1: node 2
  REQUIRE(r.rig.canio->submit({2, 0, kManufacturerWord, 2, false, 0}));  // axis 0: node 1
  const int64_t submitted = fake_now();
  std::vector<RegisterResult> results;
  std::vector<bool> configured_then;
  std::vector<int64_t> at;
  REQUIRE(r.steps.until([&] {
    RegisterResult res;
    while (r.rig.canio->poll(res)) {
      results.push_back(res);
      configured_then.push_back(r.rig.canio->axis_counters(0).configured.load());
      at.push_back(fake_now());
    }
    return results.size() == 2;
  }));
  // Axis 0's request is served once its module is configured, not held behind axis 1's.
  CHECK(results[0].tag == 2);
  CHECK_FALSE(results[0].error);
  CHECK(configured_then[0]);
  CHECK(r.rig.canio->axis_counters(0).configurations.load() == 1);
  // Axis 1's is answered kNotConfigured after 2 s of the driver's clock.
  CHECK(results[1].tag == 1);
  CHECK(results[1].error == canio::CanioBusError::kNotConfigured);
  // The 2 s count from when the driver takes the request: after the configurations that come
  // first (axis 0's, through which axis 0's request was answered too); a transfer to node 2 in
  // flight then may delay the answer by up to sdo_timeout_ms.
  const int64_t period = int64_t{r.rig.config.cycle.period_us} * 1000;
  const int64_t timeout = int64_t{r.rig.config.canio.sdo_timeout_ms} * kMs;
  CHECK(at[1] - submitted > 2000 * kMs);
  CHECK(at[1] - at[0] <= 2000 * kMs + timeout + 4 * period);
  CHECK(r.rig.canio->axis_counters(1).state.load() == canio::CanioAxisState::Configuring);
  CHECK_THAT(r.rig.canio->axis_last_error(1),
             Catch::Contains("configuring the module") && Catch::Contains("no SDO response"));
}

TEST_CASE(
    "CAN-I/O SDO: the additional-information channels are written at configuration and "
    "read every info_interval_ms",
    "[canio][sdo][engine][info]") {
  DaemonConfig c = canio_config(1);
  for (const char* name : {"temperature1", "temperature2"}) {
    const NamedInfo* n = find_named_info(name);
    REQUIRE(n != nullptr);
    c.axes[0].module.info_cmd[c.axes[0].info.size()] = encode_info_command(named_info_request(*n));
    c.axes[0].info.push_back({name, named_info_request(*n), n->is_signed});
  }
  c.canio.info_interval_ms = 100;
  Rig rig(c, true, false);
  REQUIRE_FALSE(rig.canio->start());
  Steps steps{rig};
  rig.nodes[0]->module(0).endat().encoder().set_temperature_c(55.3);
  AxisInfo info;
  info.configured = 0b0011;
  std::vector<int64_t> reads;  // fake time of each completed read
  REQUIRE(steps.until([&] {
    const AxisIo& io = rig.io[0];
    REQUIRE(io.info_acyclic);
    if (io.info_fresh) {
      update_axis_info(info, io.inputs.info_ok, io.inputs.info, fake_now());
      reads.push_back(fake_now());
    }
    return reads.size() >= 4 && info.valid == 0b0011;
  }));
  // EnDatInfoCmd01/02 as configured, written by the configuration job.
  uint32_t cmd = 0;
  REQUIRE_FALSE(rig.nodes[0]->module(0).read_register(reg::kEnDatInfoCmd01, 4, cmd));
  CHECK(cmd == encode_info_command(named_info_request(*find_named_info("temperature1"))));
  CHECK(info.value[0] == 3285);  // 55.3 °C in 0.1 K
  CHECK(info.value[1] == endat::temperature_raw(38.0));
  // One read per interval: the reads start 100 ms apart and each takes its three transfers,
  // paced one per sdo_interval_us, so completions lie within that much of the interval.
  const int64_t pacing = 3 * int64_t{c.canio.sdo_interval_us} * 1000;
  for (std::size_t i = 1; i < reads.size(); ++i) {
    CHECK(reads[i] - reads[i - 1] >= 100 * kMs - pacing);
    CHECK(reads[i] - reads[i - 1] <= 100 * kMs + pacing);
  }
  // The encoder warms up: the next read brings it.
  rig.nodes[0]->module(0).endat().encoder().set_temperature_c(80.0);
  const std::size_t before = reads.size();
  REQUIRE(steps.until([&] {
    const AxisIo& io = rig.io[0];
    if (io.info_fresh) {
      update_axis_info(info, io.inputs.info_ok, io.inputs.info, fake_now());
      reads.push_back(fake_now());
    }
    return reads.size() > before;
  }));
  CHECK(info.value[0] == endat::temperature_raw(80.0));
}

TEST_CASE(
    "CAN-I/O SDO: the check after a silence reads the configured EnDatInfoCmd0n back too, and "
    "configures a module that lost one again",
    "[canio][sdo][engine][info]") {
  DaemonConfig c = canio_config(1);
  const NamedInfo* n = find_named_info("temperature1");
  REQUIRE(n != nullptr);
  const uint32_t command = encode_info_command(named_info_request(*n));
  c.axes[0].module.info_cmd[0] = command;
  c.axes[0].info.push_back({"temperature1", named_info_request(*n), n->is_signed});
  // Configuration registers readable (the simulator's default is FM254's write-only access).
  Rig rig(c, true, false, [](sim::CanioNodeConfig& nc) { nc.faults.config_write_only = false; });
  REQUIRE_FALSE(rig.canio->start());
  Steps steps{rig};
  const auto configurations = [&] { return rig.canio->axis_counters(0).configurations.load(); };
  const auto silence = [&] {
    rig.nodes[0]->set_silent(true);
    REQUIRE(steps.until([&] { return rig.canio->axis_counters(0).silent.load(); }));
  };
  REQUIRE(steps.until([&] { return rig.io[0].inputs_fresh; }));
  REQUIRE(configurations() == 1);
  // Silent and back with everything kept: checked, not configured again.
  silence();
  rig.nodes[0]->set_silent(false);
  REQUIRE(steps.until([&] { return rig.io[0].inputs_fresh; }));
  CHECK(configurations() == 1);
  // Silent again, and meanwhile the module lost channel 1's command while EnDatMode and the MTUs
  // stayed: the check reads EnDatInfoCmd01 back, finds 0 and configures the module again.
  silence();
  REQUIRE_FALSE(rig.nodes[0]->module(0).write_register(reg::kEnDatInfoCmd01, 4, 0));
  rig.nodes[0]->set_silent(false);
  REQUIRE(steps.until([&] { return rig.io[0].inputs_fresh; }));
  CHECK(configurations() == 2);
  uint32_t cmd = 0;
  REQUIRE_FALSE(rig.nodes[0]->module(0).read_register(reg::kEnDatInfoCmd01, 4, cmd));
  CHECK(cmd == command);
}
