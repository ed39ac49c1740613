// The simulated Controlled Node's protocol core, driven in memory with frames the codec builds
// (what an MN sends) and checked on what it answers. No sockets, no sleeps: time is an argument.
#include "sim/powerlink_cn.hpp"

#include <catch2/catch.hpp>
#include <deque>
#include <functional>
#include <vector>

#include "core/clock.hpp"
#include "powerlink/frames.hpp"
#include "powerlink/process_image.hpp"
#include "powerlink/sdo.hpp"
#include "x20ds1928/sdo_mapping.hpp"

namespace pl = ds1928::powerlink;
namespace sim = ds1928::sim;
using pl::NmtState;

namespace {

constexpr pl::MacAddress kMnMac{0x02, 0, 0, 0, 0, 0xF0};
constexpr int64_t kCycle = 1'000'000;  // 1 ms

struct Harness {
  std::deque<std::vector<uint8_t>> out;  // frames the CN sent
  std::vector<std::pair<NmtState, NmtState>> transitions;
  sim::PowerlinkCn cn;
  int64_t now = 1'000'000'000;
  uint64_t relative_us = 0;
  std::array<uint8_t, pl::kMaxFrameSize> buf{};

  explicit Harness(const sim::PowerlinkCnConfig& config)
      : cn(config, [this](std::span<const uint8_t> f) { out.emplace_back(f.begin(), f.end()); }) {
    cn.set_state_listener(
        [this](NmtState from, NmtState to, int64_t) { transitions.emplace_back(from, to); });
  }

  void deliver(ds1928::Result<std::size_t> len) {
    REQUIRE(len.has_value());
    cn.receive(std::span<const uint8_t>(buf.data(), *len), now);
  }
  void soa(pl::RequestedService service, uint8_t target, NmtState mn = NmtState::kPreOperational1,
           bool er = false, bool ea = false) {
    pl::SoA s;
    s.exception_reset = er;
    s.exception_acknowledge = ea;
    s.mn_nmt_state = mn;
    s.service = service;
    s.target = target;
    deliver(pl::build_soa(buf, pl::soa_header(kMnMac), s));
  }
  void soc() {
    pl::Soc s;
    s.relative_time_us = relative_us;
    deliver(pl::build_soc(buf, pl::soc_header(kMnMac), s));
  }
  void preq(uint8_t node, std::span<const uint8_t> payload, bool ready, bool ea = false) {
    pl::PReq p;
    p.ready = ready;
    p.exception_acknowledge = ea;
    p.payload = payload;
    deliver(pl::build_preq(buf, pl::preq_header(kMnMac, cn_mac(), node), p));
  }
  void nmt(pl::NmtCommandId id, uint8_t node) {
    pl::NmtCommand c;
    c.command = static_cast<uint8_t>(id);
    deliver(pl::build_nmt_command(buf, pl::asnd_header(kMnMac, pl::kNodeMn, node), c));
  }
  void advance(int64_t ns) {
    now += ns;
    relative_us += static_cast<uint64_t>(ns / 1000);
    cn.tick(now);
  }
  // One full cycle: SoC, PReq to `node`, SoA (no service).
  void cycle(uint8_t node, std::span<const uint8_t> preq_payload, bool ready) {
    soc();
    preq(node, preq_payload, ready);
    soa(pl::RequestedService::kNone, 0, NmtState::kPreOperational2);
    advance(kCycle);
  }
  static pl::MacAddress cn_mac() { return sim::PowerlinkCnConfig{}.mac; }
  std::vector<uint8_t> pop() {
    REQUIRE_FALSE(out.empty());
    auto f = std::move(out.front());
    out.pop_front();
    return f;
  }
};

sim::PowerlinkCnConfig two_module_config() {
  sim::PowerlinkCnConfig c;
  c.node_id = 7;
  c.modules.clear();
  sim::PowerlinkCnModuleConfig m1;
  m1.slot = 1;
  m1.input_mtu = 7;
  m1.output_mtu = 7;
  sim::PowerlinkCnModuleConfig m2 = m1;
  m2.slot = 2;
  m2.input_mtu = 15;
  m2.output_mtu = 3;
  c.modules = {m1, m2};
  return c;
}

// Brings the node from power-up to PRE_OPERATIONAL_2 and returns the IdentResponse it sent.
pl::IdentResponse boot_to_pre_op2(Harness& h, uint8_t node) {
  h.soa(pl::RequestedService::kIdentRequest, node);
  REQUIRE(h.cn.nmt_state() == NmtState::kPreOperational1);
  auto frame = h.pop();
  auto asnd = pl::parse_asnd(frame);
  REQUIRE(asnd.has_value());
  const auto* ident = std::get_if<pl::IdentResponse>(&asnd->body);
  REQUIRE(ident != nullptr);
  h.advance(kCycle);
  h.soc();
  REQUIRE(h.cn.nmt_state() == NmtState::kPreOperational2);
  return *ident;
}

// Node 2 booted and cycled 5 periods: PRE_OPERATIONAL_2, its SoC period learned.
void cycle_node2(Harness& h) {
  boot_to_pre_op2(h, 2);
  std::vector<uint8_t> preq_payload(h.cn.layout().preq_size, 0);
  for (int i = 0; i < 5; ++i) h.cycle(2, preq_payload, false);
}

}  // namespace

TEST_CASE("CN boots NOT_ACTIVE to PRE_OPERATIONAL_2 and identifies with its image sizes") {
  Harness h(two_module_config());
  REQUIRE(h.cn.nmt_state() == NmtState::kNotActive);
  // An SoA for another node activates but is not answered.
  h.soa(pl::RequestedService::kIdentRequest, 9);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(h.out.empty());
  const pl::IdentResponse ident = boot_to_pre_op2(h, 7);
  const auto expected =
      pl::make_layout(std::array{pl::ModuleSpec{1, 7, 7}, pl::ModuleSpec{2, 15, 3}});
  REQUIRE(expected.has_value());
  CHECK(ident.poll_in_size == expected->pres_size);
  CHECK(ident.poll_out_size == expected->preq_size);
  CHECK(ident.poll_in_size == (16 + 7) + (16 + 15));
  CHECK(ident.poll_out_size == (2 + 7) + (2 + 3));
  CHECK(ident.nmt_state == NmtState::kPreOperational1);
  CHECK(ident.vendor_id == sim::PowerlinkCnConfig{}.vendor_id);
  const std::vector<std::pair<NmtState, NmtState>> path{
      {NmtState::kNotActive, NmtState::kPreOperational1},
      {NmtState::kPreOperational1, NmtState::kPreOperational2}};
  CHECK(std::vector(h.transitions.end() - 2, h.transitions.end()) == path);
}

TEST_CASE(
    "CN answers its PReq with a PRes carrying the modules' inputs, RD only when operational") {
  Harness h(two_module_config());
  boot_to_pre_op2(h, 7);
  std::vector<uint8_t> preq_payload(h.cn.layout().preq_size, 0);
  h.preq(7, preq_payload, false);
  auto frame = h.pop();  // the parsed PRes views these bytes
  auto pres = pl::parse_pres(frame);
  REQUIRE(pres.has_value());
  CHECK(pres->nmt_state == NmtState::kPreOperational2);
  CHECK_FALSE(pres->ready);
  CHECK(pres->payload.size() == h.cn.layout().pres_size);
  // PReq for another node: no answer.
  h.preq(8, preq_payload, false);
  CHECK(h.out.empty());

  h.nmt(pl::NmtCommandId::kStartNode, 7);  // not allowed from PRE_OPERATIONAL_2
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational2);
  h.nmt(pl::NmtCommandId::kEnableReadyToOperate, 7);
  CHECK(h.cn.nmt_state() == NmtState::kReadyToOperate);
  h.nmt(pl::NmtCommandId::kStartNode, 7);
  CHECK(h.cn.nmt_state() == NmtState::kOperational);

  h.preq(7, preq_payload, true);
  frame = h.pop();
  pres = pl::parse_pres(frame);
  REQUIRE(pres.has_value());
  CHECK(pres->ready);
  CHECK(pres->nmt_state == NmtState::kOperational);
  ds1928::ModuleInputs in;
  const auto* m1 = h.cn.layout().find(1);
  REQUIRE(m1 != nullptr);
  REQUIRE(pl::read_inputs(pres->payload, *m1, in));
  const ds1928::ModuleInputs direct = h.cn.module(0).inputs();
  CHECK(in.position_hw == direct.position_hw);
  CHECK(in.position_lw == direct.position_lw);
  CHECK(in.pos_time_us == direct.pos_time_us);
}

TEST_CASE("CN modules take NetTime from the SoC RelativeTime") {
  sim::PowerlinkCnConfig config;
  config.node_id = 3;
  Harness h(config);
  boot_to_pre_op2(h, 3);
  h.relative_us = 0x1'2345'6789ULL;  // beyond 32 bits: PosTime is the low word
  std::vector<uint8_t> preq_payload(h.cn.layout().preq_size, 0);
  // Enable the encoder through the register so that the module stamps positions.
  REQUIRE_FALSE(
      h.cn.module(0).write_register(ds1928::reg::kEnDatMode, 1, ds1928::endat_mode::kEnable));
  for (int i = 0; i < 20; ++i) {
    h.soc();
    h.preq(3, preq_payload, false);
    h.out.clear();
    h.advance(kCycle);
  }
  h.soc();
  h.preq(3, preq_payload, false);
  const auto frame = h.pop();  // the parsed PRes views these bytes
  auto pres = pl::parse_pres(frame);
  REQUIRE(pres.has_value());
  ds1928::ModuleInputs in;
  REQUIRE(pl::read_inputs(pres->payload, *h.cn.layout().find(1), in));
  const auto soc_low = static_cast<uint32_t>(h.relative_us);
  // The stamp is the NetTime of the module's last EnDat cycle: at or shortly before this SoC.
  const auto age = static_cast<int32_t>(soc_low - in.pos_time_us);
  CHECK(age >= 0);
  CHECK(age < 2000);
}

TEST_CASE("CN SDO server maps objects onto the module registers") {
  sim::PowerlinkCnConfig config;
  config.node_id = 5;
  Harness h(config);
  boot_to_pre_op2(h, 5);

  std::deque<std::vector<uint8_t>> client_out;
  std::error_code done_ec = make_error_code(pl::SdoError::kTimeout);
  std::vector<uint8_t> done_data;
  bool done = false;
  pl::SdoClientConfig cc;
  cc.node = 5;
  cc.own_mac = kMnMac;
  pl::SdoClient client(
      cc, [&](std::span<const uint8_t> f) { client_out.emplace_back(f.begin(), f.end()); },
      [&](std::error_code ec, std::span<const uint8_t> data) {
        done = true;
        done_ec = ec;
        done_data.assign(data.begin(), data.end());
      });
  // Shuttle: client frames go to the CN directly (MN's own async slot); CN answers go out only
  // when invited.
  auto run = [&] {
    for (int round = 0; round < 50 && !done; ++round) {
      while (!client_out.empty()) {
        auto f = std::move(client_out.front());
        client_out.pop_front();
        h.cn.receive(f, h.now);
      }
      h.soa(pl::RequestedService::kUnspecifiedInvite, 5, NmtState::kPreOperational2);
      while (!h.out.empty()) {
        auto f = h.pop();
        auto asnd = pl::parse_asnd(f);
        REQUIRE(asnd.has_value());
        if (const auto* sdo = std::get_if<pl::Sdo>(&asnd->body)) client.receive(*sdo, h.now);
      }
      h.advance(kCycle);
      client.tick(h.now);
    }
  };
  const ds1928::SdoMapping mapping;
  const auto mode_obj = mapping.object_for(1, ds1928::reg::kEnDatMode);
  REQUIRE(mode_obj.has_value());
  const uint8_t mode_value = ds1928::endat_mode::kEnable | ds1928::endat_mode::kSigned;
  REQUIRE_FALSE(client.write(mode_obj->index, mode_obj->subindex,
                             std::span<const uint8_t>(&mode_value, 1), h.now));
  run();
  REQUIRE(done);
  CHECK_FALSE(done_ec);
  uint32_t reg_value = 0;
  REQUIRE_FALSE(h.cn.module(0).read_register(ds1928::reg::kEnDatMode, 1, reg_value));
  CHECK(reg_value == mode_value);

  done = false;
  REQUIRE_FALSE(client.read(0x1018, 1, h.now));
  run();
  REQUIRE(done);
  CHECK_FALSE(done_ec);
  REQUIRE(done_data.size() == 4);
  CHECK(pl::load_le32(done_data.data()) == config.vendor_id);

  // Slot 2 does not exist on this node: the server aborts with "object does not exist".
  done = false;
  const auto missing = mapping.object_for(2, ds1928::reg::kEnDatMode);
  REQUIRE(missing.has_value());
  REQUIRE_FALSE(client.read(missing->index, missing->subindex, h.now));
  run();
  REQUIRE(done);
  CHECK(done_ec == ds1928::make_sdo_abort_error(0x06020000));
}

TEST_CASE("CN loss of SoC falls back to PRE_OPERATIONAL_1 and logs it in the StatusResponse") {
  sim::PowerlinkCnConfig config;
  config.node_id = 2;
  Harness h(config);
  cycle_node2(h);
  h.out.clear();
  h.advance(config.soc_timeout_min_ns + kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(h.cn.stats().loss_of_soc == 1);
  h.soa(pl::RequestedService::kStatusRequest, 2);
  const auto frame = h.pop();  // the parsed ASnd views these bytes
  auto asnd = pl::parse_asnd(frame);
  REQUIRE(asnd.has_value());
  const auto* status = std::get_if<pl::StatusResponse>(&asnd->body);
  REQUIRE(status != nullptr);
  REQUIRE(status->entry_count() == 1);
  CHECK(status->entry(0).code == 0x8245);
  CHECK(status->exception_new);
}

TEST_CASE("CN loss of SoC: a span the simulator itself was stopped by its host is not silence") {
  sim::PowerlinkCnConfig config;
  config.node_id = 2;
  Harness h(config);
  cycle_node2(h);
  // 30 ms without a SoC, 29 of them with the simulator stopped: 1 ms seen, no loss.
  h.cn.note_own_stall(h.now + 500'000, h.now + 29'500'000);
  h.advance(30 * kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational2);
  CHECK(h.cn.stats().loss_of_soc == 0);
  CHECK(h.cn.stats().own_stalls == 1);
  CHECK(h.cn.stats().own_stall_max_ns == 29'000'000);
  // A SoC restarts the count: a stall noted before it is not credited to the next silence.
  h.soc();
  h.cn.note_own_stall(h.now - 20 * kCycle, h.now - kCycle);
  // Silence the simulator was there to see counts in full, stalls before it included.
  h.advance(config.soc_timeout_min_ns - kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational2);
  h.advance(2 * kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(h.cn.stats().loss_of_soc == 1);
}

TEST_CASE("CN loss of SoC: stalls add up only over what the simulator did not see") {
  sim::PowerlinkCnConfig config;
  config.node_id = 2;
  Harness h(config);
  cycle_node2(h);
  const int64_t last_soc = h.now - kCycle;  // cycle() advanced one period after its SoC
  // Two stalls of 3 ms with 3 ms seen between and after: 6 ms seen of 12 ms, a loss of SoC.
  h.cn.note_own_stall(h.now, h.now + 3 * kCycle);
  h.cn.note_own_stall(h.now + 6 * kCycle, h.now + 9 * kCycle);
  h.advance(10 * kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational2);  // 11 ms since the SoC, 5 ms seen
  h.advance(kCycle);
  CHECK(h.now - last_soc == 12 * kCycle);
  CHECK(h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(h.cn.stats().own_stalls == 2);
}

TEST_CASE("CN reset and power cycle bring it back to NOT_ACTIVE with module defaults") {
  sim::PowerlinkCnConfig config;
  config.node_id = 4;
  config.power_off_ns = 50'000'000;
  Harness h(config);
  boot_to_pre_op2(h, 4);
  REQUIRE_FALSE(h.cn.module(0).write_register(ds1928::reg::kEnDatMode, 1, 1));
  h.nmt(pl::NmtCommandId::kResetCommunication, 4);
  CHECK(h.cn.nmt_state() == NmtState::kNotActive);
  uint32_t v = 0;
  REQUIRE_FALSE(h.cn.module(0).read_register(ds1928::reg::kEnDatMode, 1, v));
  CHECK(v == 1);  // reset communication keeps the application's configuration
  boot_to_pre_op2(h, 4);
  h.nmt(pl::NmtCommandId::kResetNode, 4);
  CHECK(h.cn.nmt_state() == NmtState::kNotActive);
  REQUIRE_FALSE(h.cn.module(0).read_register(ds1928::reg::kEnDatMode, 1, v));
  CHECK(v == 0);  // reset node resets the application: bus-controller defaults

  boot_to_pre_op2(h, 4);
  h.cn.power_cycle(h.now);
  CHECK(h.cn.nmt_state() == NmtState::kOff);
  h.soa(pl::RequestedService::kIdentRequest, 4);
  CHECK(h.out.empty());  // no power, no answer
  h.advance(config.power_off_ns + 1);
  CHECK(h.cn.nmt_state() == NmtState::kNotActive);
  CHECK(h.cn.stats().power_cycles == 1);
}

TEST_CASE("CN fault injection: dropped, delayed and wrongly sized PRes") {
  sim::PowerlinkCnConfig config;
  config.node_id = 6;
  config.faults.drop_pres = 0.25;
  config.faults.seed = 42;
  Harness h(config);
  boot_to_pre_op2(h, 6);
  std::vector<uint8_t> preq_payload(h.cn.layout().preq_size, 0);
  int answered = 0;
  constexpr int kRequests = 2000;
  for (int i = 0; i < kRequests; ++i) {
    h.preq(6, preq_payload, false);
    answered += static_cast<int>(h.out.size());
    h.out.clear();
  }
  const double loss = 1.0 - static_cast<double>(answered) / kRequests;
  CHECK(loss > 0.20);
  CHECK(loss < 0.30);
  CHECK(h.cn.stats().pres_dropped == static_cast<uint64_t>(kRequests - answered));

  sim::PowerlinkCnFaults faults;
  faults.delay_pres = 1.0;
  faults.delay_pres_ns = 300'000;
  h.cn.set_faults(faults);
  h.preq(6, preq_payload, false);
  CHECK(h.out.empty());
  CHECK(h.cn.next_deadline_ns() == h.now + 300'000);
  h.now += 299'000;
  h.cn.tick(h.now);
  CHECK(h.out.empty());
  h.now += 1'000;
  h.cn.tick(h.now);
  REQUIRE(h.out.size() == 1);
  const auto late = h.pop();
  CHECK(pl::parse_pres(late).has_value());

  faults = {};
  faults.pres_size_delta = 4;
  h.cn.set_faults(faults);
  h.preq(6, preq_payload, false);
  const auto frame = h.pop();  // the parsed PRes views these bytes
  auto pres = pl::parse_pres(frame);
  REQUIRE(pres.has_value());
  CHECK(pres->payload.size() == h.cn.layout().pres_size + 4u);
}

namespace {
// A StatusRequest with ER/EA; returns the StatusResponse's bytes (the parsed view needs them).
std::vector<uint8_t> status_request(Harness& h, uint8_t node, bool er, bool ea) {
  h.out.clear();
  h.soa(pl::RequestedService::kStatusRequest, node, NmtState::kPreOperational2, er, ea);
  return h.pop();
}
pl::StatusResponse status_of(const std::vector<uint8_t>& frame) {
  auto asnd = pl::parse_asnd(frame);
  REQUIRE(asnd.has_value());
  const auto* status = std::get_if<pl::StatusResponse>(&asnd->body);
  REQUIRE(status != nullptr);
  return *status;
}
}  // namespace

TEST_CASE("CN error signalling: EC follows ER, a raised entry toggles EN until EA comes back") {
  sim::PowerlinkCnConfig config;
  config.node_id = 3;
  Harness h(config);
  boot_to_pre_op2(h, 3);
  // After power-up EC=1: the MN sees the reboot.
  auto f = status_request(h, 3, false, false);
  CHECK(status_of(f).exception_clear);
  f = status_request(h, 3, true, false);  // ER=1: the answer to it already has EC=1
  CHECK(status_of(f).exception_clear);
  f = status_request(h, 3, false, false);  // ER=0: EC=0
  CHECK_FALSE(status_of(f).exception_clear);
  CHECK_FALSE(status_of(f).exception_new);
  CHECK(status_of(f).entry_count() == 0);

  h.cn.raise_error(0x1928, {9, 0, 0, 0, 0, 0, 0, 0}, h.now);
  CHECK(h.cn.error_signalling().exception_new());
  std::vector<uint8_t> payload(h.cn.layout().preq_size, 0);
  h.out.clear();
  h.soc();
  h.preq(3, payload, false, false);
  const auto pres_frame = h.pop();
  auto pres = pl::parse_pres(pres_frame);
  REQUIRE(pres.has_value());
  CHECK(pres->exception_new);  // EN in the PRes
  f = status_request(h, 3, false, false);
  const auto st = status_of(f);
  CHECK(st.exception_new);
  CHECK(st.static_error_bits == pl::kErrorRegisterGeneric);
  REQUIRE(st.entry_count() == 1);
  CHECK(st.entry(0).code == 0x1928);
  CHECK(st.entry(0).type == (pl::entry_type::kEmergency | pl::entry_type::kModeOccurred |
                             pl::entry_type::kProfileVendor));
  CHECK(st.entry(0).additional[0] == 9);
  // Not acknowledged yet: the entry is sent again.
  f = status_request(h, 3, false, false);
  CHECK(status_of(f).entry_count() == 1);
  // EA = EN in the PReq: delivered.
  h.preq(3, payload, false, true);
  f = status_request(h, 3, false, true);
  CHECK(status_of(f).entry_count() == 0);
  CHECK(status_of(f).static_error_bits == 0);
  CHECK(status_of(f).exception_new);  // EN stays where it is until the next entry
  // A reset: EC=1 again, the queue is empty.
  h.cn.raise_error(0x1929, {}, h.now);
  h.nmt(pl::NmtCommandId::kResetNode, 3);
  boot_to_pre_op2(h, 3);
  f = status_request(h, 3, false, false);
  CHECK(status_of(f).exception_clear);
  CHECK(status_of(f).entry_count() == 0);
}

TEST_CASE("CN objects an MN's configuration manager writes: store, restore, DLL counters") {
  sim::CnObjectDictionary od;
  const std::array<uint8_t, 4> save{'s', 'a', 'v', 'e'};
  const std::array<uint8_t, 4> load{'l', 'o', 'a', 'd'};
  const std::array<uint8_t, 4> date{0x24, 0x31, 0, 0};
  const std::array<uint8_t, 4> threshold{0x50, 0, 0, 0};
  CHECK(od.write(0x1020, 1, date) == 0);
  CHECK(od.write(0x1C0B, 3, threshold) == 0);
  CHECK(od.write(0x1C0D, 3, threshold) == 0);
  CHECK(od.write(0x1C0B, 2, threshold) == 0x06010002);  // threshold counter: read-only
  CHECK(od.write(0x1C0B, 4, threshold) == 0x06090011);
  CHECK(od.write(0x1010, 1, load) == 0x08000020);  // wrong signature
  CHECK(od.write(0x6000, 1, threshold) == 0x06020000);
  std::array<uint8_t, 8> out{};
  std::size_t size = 0;
  CHECK(od.read(0x1C0D, 3, out, size) == 0);
  CHECK(size == 4);
  CHECK(out[0] == 0x50);
  // NMTResetConfiguration keeps the values (the caller does not reset), a reset of the
  // communication goes back to the stored ones, else the defaults.
  od.reset_communication();
  CHECK(od.configuration_date() == 0);
  CHECK(od.write(0x1020, 1, date) == 0);
  CHECK(od.write(0x1010, 1, save) == 0);
  od.reset_communication();
  CHECK(od.configuration_date() == 0x3124);
  CHECK(od.write(0x1011, 1, load) == 0);
  CHECK(od.configuration_date() == 0x3124);  // still in use until the next reset
  od.reset_communication();
  CHECK(od.configuration_date() == 0);
}

namespace {

// A link with nothing on it: the MN has gone quiet.
class QuietLink final : public pl::Link {
 public:
  std::error_code send(std::span<const uint8_t>) noexcept override { return {}; }
  pl::Received receive(std::span<uint8_t>, int64_t) noexcept override { return {}; }
  bool link_up() const noexcept override { return true; }
  pl::MacAddress mac() const noexcept override { return Harness::cn_mac(); }
};

// The node booted and cycling on the real clock (the loop reads it), then one pass of the loop
// whose wait comes back `stall_ns` late: the thread stopped there. `run_queue_wait` is what the
// kernel counted meanwhile as waiting for a CPU of this machine.
struct StalledPass {
  sim::PowerlinkCnConfig config;
  Harness h;
  QuietLink link;
  explicit StalledPass(int64_t soc_timeout_ns) : config(make(soc_timeout_ns)), h(config) {
    // The boot and 5 cycles on the harness' clock, exactly one period apart, all of it in the
    // real clock's recent past: the period the node learns does not depend on how fast this
    // machine ran the steps (under a sanitizer the first steps alone can take 100 ms).
    h.now = ds1928::rt::now_ns() - 20 * kCycle;
    boot_to_pre_op2(h, 2);
    std::vector<uint8_t> preq_payload(h.cn.layout().preq_size, 0);
    for (int i = 0; i < 5; ++i) {
      h.advance(kCycle);
      h.soc();
      h.preq(2, preq_payload, false);
    }
    // Nothing left to send: the loop has no node deadline and blocks in its wait.
    h.cn.tick(h.now + kCycle / 2);
    REQUIRE(h.cn.next_deadline_ns() == INT64_MAX);
    REQUIRE(h.now < ds1928::rt::now_ns());
  }
  static sim::PowerlinkCnConfig make(int64_t soc_timeout_ns) {
    sim::PowerlinkCnConfig c;
    c.node_id = 2;
    c.soc_timeout_min_ns = soc_timeout_ns;
    return c;
  }
  void run(int64_t stall_ns, std::function<int64_t()> run_queue_wait) {
    sim::PowerlinkCnLoop::Options options;
    options.run_queue_wait_ns = std::move(run_queue_wait);
    sim::PowerlinkCn* nodes[] = {&h.cn};
    // No SoC rhythm known to the loop: it blocks in wait_readable, which returns stall_ns after
    // its deadline (a sleep lasts at least as long as asked: the stall is certain).
    sim::PowerlinkCnLoop loop(
        link,
        [stall_ns](int64_t deadline) {
          (void)ds1928::rt::sleep_until(deadline + stall_ns);
          return false;
        },
        nodes, options);
    REQUIRE(loop.run_once());
  }
};

}  // namespace

TEST_CASE("CN loop: its host stopping the simulator's thread is not counted as loss of SoC") {
  // Loss of SoC after 1 s seen; the pass stops 1.5 s. What the simulator sees besides (the
  // harness' cycles some ms back, the pass' own 1 ms of polling) stays far below 1 s even on a
  // loaded machine.
  StalledPass p(1'000'000'000);
  p.run(1'500'000'000, [] { return int64_t{5'000}; });  // the kernel counted no wait
  CHECK(p.h.cn.nmt_state() == NmtState::kPreOperational2);
  CHECK(p.h.cn.stats().loss_of_soc == 0);
  // At least the one stall: the fake count says "no run-queue wait" for every check, so a
  // preemption of this test's thread in the pass' polling (make stress) counts as one more.
  CHECK(p.h.cn.stats().own_stalls >= 1);
  CHECK(p.h.cn.stats().own_stall_max_ns >= 1'500'000'000);
}

TEST_CASE("CN loop: a task of this machine running instead of the simulator is still silence") {
  StalledPass p(100'000'000);
  int64_t waited = 0;
  // The kernel counted the whole stall (and more) as run-queue wait: nothing is the host's.
  p.run(300'000'000, [&waited] { return waited += 1'000'000'000; });
  CHECK(p.h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(p.h.cn.stats().loss_of_soc == 1);
  CHECK(p.h.cn.stats().own_stalls == 0);
}

TEST_CASE("CN loop: without the kernel's run-queue count every stall is silence") {
  StalledPass p(100'000'000);
  p.run(300'000'000, {});
  CHECK(p.h.cn.nmt_state() == NmtState::kPreOperational1);
  CHECK(p.h.cn.stats().loss_of_soc == 1);
}

TEST_CASE("CN loop rhythm: a pause of the MN is not its new period, a longer cycle is") {
  sim::PowerlinkCnLoop::Rhythm r;
  int64_t t = 1'000'000'000;
  for (int i = 0; i < 20; ++i) r.note(t += kCycle);
  CHECK(r.period == kCycle);
  // The MN's host stalls 9 ms once, then cycles on: the loop keeps sleeping by 1 ms.
  r.note(t += 9 * kCycle);
  CHECK(r.period == kCycle);
  r.note(t += kCycle);
  CHECK(r.period == kCycle);
  CHECK(r.valid(t + kCycle));
  // The MN restarted with a 10 ms cycle: the second long gap in a row is the period.
  r.note(t += 10 * kCycle);
  CHECK(r.period == kCycle);
  r.note(t += 10 * kCycle);
  CHECK(r.period == 10 * kCycle);
  for (int i = 0; i < 5; ++i) r.note(t += 10 * kCycle);
  CHECK(r.period == 10 * kCycle);
  // A shorter cycle is followed by the average.
  for (int i = 0; i < 100; ++i) r.note(t += kCycle);
  CHECK(r.period < kCycle + kCycle / 10);
}
