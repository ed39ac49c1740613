// ds1928d's MN configures the simulated CN without modules (a generic CN) the way a
// configuration manager does: the concise DCF's objects written by SDO in the boot step
// "configure", and the CN's process image follows them (0x1F98, 0x1A00). In process, simulated
// time, no sockets. Also the CN's object dictionary on its own.
#include <catch2/catch.hpp>
#include <deque>
#include <vector>

#include "powerlink/concise_dcf.hpp"
#include "powerlink/link.hpp"
#include "powerlink/powerlink_bus.hpp"
#include "sim/cn_object_dictionary.hpp"
#include "sim/powerlink_cn.hpp"

namespace pl = ds1928::powerlink;
namespace sim = ds1928::sim;

namespace {

int64_t g_now_ns = 1'000'000'000;
int64_t fake_clock() noexcept {
  return g_now_ns;
}
constexpr int64_t kCycleNs = 1'000'000;

class Wire final : public pl::Link {
 public:
  sim::PowerlinkCn* cn = nullptr;
  std::deque<std::vector<uint8_t>> to_mn;
  std::error_code send(std::span<const uint8_t> frame) noexcept override {
    g_now_ns += 2'000;
    cn->receive(frame, g_now_ns);
    return {};
  }
  pl::Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override {
    if (to_mn.empty()) {
      if (deadline_ns > g_now_ns) g_now_ns = deadline_ns;
      return {};
    }
    auto f = std::move(to_mn.front());
    to_mn.pop_front();
    std::copy_n(f.begin(), std::min(f.size(), buffer.size()), buffer.begin());
    g_now_ns += 2'000;
    return {f.size(), g_now_ns, {}};
  }
  bool link_up() const noexcept override { return true; }
  pl::MacAddress mac() const noexcept override { return {0x02, 0, 0, 0, 0, 0xF0}; }
};

std::vector<uint8_t> le(uint64_t v, int n) {
  std::vector<uint8_t> d;
  // Bytes past the eighth (a write one byte too long for a U64) are 0: no shift by 64.
  for (int i = 0; i < n; ++i) d.push_back(i < 8 ? static_cast<uint8_t>(v >> (8 * i)) : 0);
  return d;
}

}  // namespace

TEST_CASE(
    "The MN configures a generic simulated CN from a concise DCF, its PRes follows the "
    "written mapping",
    "[integration][powerlink][generic]") {
  // What openCONFIGURATOR puts into 0x1F22/9 for such a CN: cycle, tolerance, mapping (disable,
  // entries, enable), PReq limit.
  const std::vector<pl::CdcEntry> dcf = {
      {0x1006, 0, le(1000, 4)},
      {0x1C14, 0, le(100'000, 4)},
      {0x1800, 1, {0}},
      {0x1A00, 0, {0}},
      {0x1A00, 1, le(pl::PdoMapEntry{0x6000, 1, 0, 64}.to_u64(), 8)},
      {0x1A00, 2, le(pl::PdoMapEntry{0x6000, 2, 64, 16}.to_u64(), 8)},
      {0x1A00, 0, {2}},
      {0x1F98, 4, le(4, 2)},
  };
  const auto decoded = pl::decode_cdc(pl::encode_cdc(dcf));
  REQUIRE(decoded.ok());
  ds1928::PowerlinkNodeConfig node;
  node.node_id = 9;
  node.pres_timeout_us = 200;
  node.vendor_id = 0x1A;
  node.product_code = 0x1928;
  for (const auto& e : decoded.entries)
    node.object_writes.push_back({e.index, e.subindex, e.data, true});
  node.object_writes.push_back({0x1234, 0, {1}, false});  // the CN has no such object

  Wire wire;
  sim::PowerlinkCnConfig cn_config;
  cn_config.node_id = 9;
  cn_config.modules.clear();  // no modules: a generic CN
  sim::PowerlinkCn cn(
      cn_config, [&](std::span<const uint8_t> f) { wire.to_mn.emplace_back(f.begin(), f.end()); });
  wire.cn = &cn;
  pl::MnConfig mn_config;
  mn_config.bus.nodes.push_back(node);
  mn_config.cycle_us = 1000;
  mn_config.mac = wire.mac();
  // Listening for another MN first (MNWaitNotAct) has tests of its own; these start at once.
  mn_config.bus.nmt.wait_not_active_ms = 0;
  pl::PowerlinkBus mn(mn_config, wire);
  mn.set_clock(&fake_clock);
  REQUIRE_FALSE(mn.start());
  std::vector<ds1928::AxisIo> io;
  uint64_t cycle = 0;
  auto step = [&] {
    const int64_t start = (g_now_ns / kCycleNs + 1) * kCycleNs;
    g_now_ns = start;
    cn.tick(g_now_ns);
    auto r = mn.exchange(io, start, cycle++);
    cn.tick(g_now_ns);
    return r;
  };
  bool up = false;
  for (int i = 0; i < 3000 && !up; ++i) up = step().bus_up;
  REQUIRE(up);
  CHECK(cn.nmt_state() == pl::NmtState::kOperational);
  for (int i = 0; i < 5; ++i) step();

  const pl::PowerlinkStatus st = mn.status();
  REQUIRE(st.node_count == 1);
  const pl::CnStatus& n = st.nodes[0];
  CHECK(n.objects_written == dcf.size());
  CHECK(n.object_failures == 1);
  REQUIRE(n.last_failure_count == 1);
  CHECK(pl::describe(n.last_failures[0]) ==
        "0x1234/0 write: " + ds1928::make_sdo_abort_error(0x06020000).message());
  // The CN's PRes is what its mapping says (80 bits), its PReq the written limit.
  pl::PresSnapshot snap;
  REQUIRE(mn.pres_snapshot(9, snap));
  CHECK(snap.fresh);
  CHECK(snap.size == 10);
  CHECK(n.pres_size == 10);
  CHECK(n.preq_size == 4);
  CHECK(n.pres_size_mismatches == 0);
  CHECK(n.resets == 0);
}

TEST_CASE("The simulated CN's communication objects: typed access, mapping rules, sizes",
          "[sim][powerlink][od]") {
  sim::CnObjectDictionary od;
  std::array<uint8_t, 16> out{};
  std::size_t size = 0;
  CHECK(od.write(0x1006, 0, le(2000, 4)) == 0);
  CHECK(od.cycle_length_us() == 2000);
  CHECK(od.write(0x1006, 0, le(2000, 2)) == 0x06070010);  // wrong length
  CHECK(od.write(0x1006, 1, le(2000, 4)) == 0x06090011);  // no such subindex
  CHECK(od.read(0x1006, 0, out, size) == 0);
  CHECK(size == 4);
  CHECK(out[0] == 0xD0);
  CHECK(od.write(0x1F98, 1, le(10, 2)) == 0x06010002);  // the device's own limit: read only
  CHECK(od.write(0x1F98, 5, le(1491, 2)) == 0x06090030);
  CHECK(od.pres_size(23) == 23);
  // Mapping: entries only while disabled (sub 0 = 0), then enabled with the count.
  CHECK(od.write(0x1A00, 1, le(pl::PdoMapEntry{0x6000, 1, 0, 32}.to_u64(), 8)) == 0);
  CHECK(od.write(0x1A00, 0, std::vector<uint8_t>{1}) == 0);
  CHECK(od.pres_size(0) == 4);
  CHECK(od.pres_size(23) == 23);  // the modules' image stays whole
  CHECK(od.write(0x1A00, 2, le(1, 8)) == 0x08000022);
  CHECK(od.read(0x1A00, 0, out, size) == 0);
  CHECK((size == 1 && out[0] == 1));
  CHECK(od.write(0x1F98, 5, le(40, 2)) == 0);
  CHECK(od.pres_size(23) == 40);  // the configured limit wins
  CHECK(od.write(0x1F22, 9, std::vector<uint8_t>{1, 2, 3}) == 0);
  CHECK(od.read(0x1F22, 9, out, size) == 0);
  CHECK(size == 3);
  od.reset_communication();  // nothing stored (0x1010): the defaults
  CHECK(od.pres_size(23) == 23);
  CHECK(od.cycle_length_us() == 0);
  CHECK(sim::CnObjectDictionary::handles(0x1400));
  CHECK_FALSE(sim::CnObjectDictionary::handles(0x2001));
}

TEST_CASE("The simulated CN's object dictionary serves every CN row of the standard table",
          "[sim][powerlink][od][standard_objects]") {
  sim::CnObjectDictionary od;
  od.set_identity(0x191, 0x1A, 0x1928, 3, 77);
  std::array<uint8_t, 16> out{};
  for (const pl::StandardObject& o : pl::kStandardObjects) {
    const bool cn = o.holder == pl::ObjHolder::kCn;
    INFO(pl::object_name(o.index, o.sub_first) << " " << o.name);
    CHECK(sim::CnObjectDictionary::handles(o.index) ==
          pl::has_standard_index(o.index, pl::ObjHolder::kCn));
    if (!cn || o.type == pl::ObjType::kDomain) continue;
    const int width = static_cast<int>(pl::type_size(o.type));
    const unsigned last =
        std::min<unsigned>(o.sub_last, o.sub_first + sim::CnObjectDictionary::kMaxMapped - 1);
    for (unsigned s = o.sub_first; s <= last; ++s) {
      const auto sub = static_cast<uint8_t>(s);
      std::size_t size = 0;
      REQUIRE(od.read(o.index, sub, out, size) == 0);
      CHECK(size == static_cast<std::size_t>(width));  // typed by the table
      uint64_t v = 0;
      for (std::size_t i = 0; i < size; ++i) v |= uint64_t{out[i]} << (8 * i);
      if (o.access != pl::ObjAccess::kRo) CHECK(v == o.default_value);
      // Access from the table: a write of the device's own values is refused; a writable one
      // of the wrong length too.
      if (o.access != pl::ObjAccess::kRw) {
        CHECK(od.write(o.index, sub, le(v, width)) == 0x06010002);
      } else {
        CHECK(od.write(o.index, sub, le(v, width + 1)) == 0x06070010);
      }
    }
  }
  // The identity the CN was given, read back as an MN's identity check reads it.
  std::size_t size = 0;
  REQUIRE(od.read(pl::obj::kIdentity, 2, out, size) == 0);
  CHECK((size == 4 && out[0] == 0x28 && out[1] == 0x19));
  REQUIRE(od.read(pl::obj::kDeviceType, 0, out, size) == 0);
  CHECK((out[0] == 0x91 && out[1] == 0x01));
  CHECK(od.read(pl::obj::kIdentity, 5, out, size) == 0x06090011);         // no such sub-index
  CHECK(od.read(pl::obj::kMnCnPResTimeout, 1, out, size) == 0x06020000);  // an MN's object
  // A reset keeps the device's own values and returns the written ones to their defaults.
  CHECK(od.write(pl::obj::kCycleLen, 0, le(4000, 4)) == 0);
  od.reset_communication();
  CHECK(od.cycle_length_us() == 0);
  REQUIRE(od.read(pl::obj::kIdentity, 4, out, size) == 0);
  CHECK(out[0] == 77);
}
