// The powerlink section's third-party CN keys: no axes at all, typed SDO writes, concise DCF
// files (the node's own and the MN's mnobd.cdc with 0x1F22/node), identity and sizes from them.
#include <stdlib.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <string>

#include "config/config_loader.hpp"
#include "config_test_util.hpp"
#include "powerlink/concise_dcf.hpp"

namespace {

using namespace ds1928;
using powerlink::CdcEntry;
using test::from;
using test::le;
using test::one_error;

// A private directory for CDC files, removed at the end.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    std::string t = (std::filesystem::temp_directory_path() / "ds1928-cfgpl-XXXXXX").string();
    REQUIRE(::mkdtemp(t.data()) != nullptr);
    path = t;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  std::string write(const std::string& name, const std::vector<uint8_t>& bytes) const {
    std::ofstream(path / name, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
    return (path / name).string();
  }
};

const std::string kHead = "bus: powerlink\npowerlink:\n  interface: veth0\n  nodes:\n";

TEST_CASE("A POWERLINK configuration without axes is valid", "[config][powerlink]") {
  const ConfigResult r = from(kHead + "    - {node_id: 5, preq_size: 4, pres_size: 8}\n");
  INFO(r.error_report());
  REQUIRE(r.ok());
  CHECK(r.config().axes.empty());
  CHECK(r.config().powerlink.nodes[0].pres_size == uint16_t{8});
  const ConfigResult again = from(dump_config(r.config()));
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(dump_config(again.config()) == dump_config(r.config()));
}

TEST_CASE("sdo_writes take one typed value each, little endian", "[config][powerlink]") {
  const ConfigResult r = from(kHead +
                              "    - node_id: 1\n"
                              "      sdo_writes:\n"
                              "        - {index: 0x1006, u32: 1000}\n"
                              "        - {index: 0x1F98, subindex: 5, u16: 0x24}\n"
                              "        - {index: 0x2000, subindex: 1, i16: -2}\n"
                              "        - {index: 0x2001, subindex: 2, domain: \"01 0a FF\"}\n"
                              "        - {index: 0x2002, u64: 0x0010000000016200}\n");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const auto& w = r.config().powerlink.nodes[0].object_writes;
  REQUIRE(w.size() == 5);
  CHECK(w[0] == CnObjectWrite{0x1006, 0, le(1000, 4), false});
  CHECK(w[1] == CnObjectWrite{0x1F98, 5, {0x24, 0}, false});
  CHECK(w[2].data == std::vector<uint8_t>{0xFE, 0xFF});
  CHECK(w[3].data == std::vector<uint8_t>{0x01, 0x0A, 0xFF});
  CHECK(w[4].data == le(0x0010000000016200ULL, 8));
  // 0x1F98/5 written: that is the PRes payload size.
  CHECK(r.config().powerlink.nodes[0].pres_size == uint16_t{0x24});
  const ConfigResult again = from(dump_config(r.config()));
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(again.config().powerlink.nodes[0].object_writes.size() == 5);
  CHECK(dump_config(again.config()) == dump_config(r.config()));

  const std::string at = kHead + "    - node_id: 1\n      sdo_writes:\n        - ";
  CHECK_THAT(one_error(at + "{index: 0x1006}\n"),
             Catch::Contains("powerlink.nodes[0].sdo_writes[0]: missing the value: give exactly "
                             "one of u8, u16, u32, u64, i8, i16, i32, i64, domain"));
  CHECK_THAT(one_error(at + "{index: 0x1006, u8: 1, u16: 2}\n"),
             Catch::Contains("more than one value given (u8, u16)"));
  CHECK_THAT(one_error(at + "{index: 0x1006, u8: 256}\n"),
             Catch::Contains("sdo_writes[0].u8: 256 is out of range 0..255"));
  CHECK_THAT(one_error(at + "{index: 0x1006, domain: \"0g\"}\n"),
             Catch::Contains("sdo_writes[0].domain: '0g' is not a list of hex bytes"));
  CHECK_THAT(one_error(at + "{u8: 1}\n"), Catch::Contains("sdo_writes[0].index: missing"));
  CHECK_THAT(one_error(at + "{index: 0x1006, u32: 1, typo: 2}\n"),
             Catch::Contains("unknown key 'typo'"));
}

TEST_CASE("A node's concise DCF becomes its writes, its mapping gives the payload sizes",
          "[config][powerlink][cdc]") {
  TempDir dir;
  const std::vector<CdcEntry> node_cdc = {
      {0x1006, 0, le(1000, 4)},
      {0x1A00, 0, {1}},
      {0x1A00, 1, le(powerlink::PdoMapEntry{0x6000, 1, 0, 80}.to_u64(), 8)},
      {0x1600, 0, {1}},
      {0x1600, 1, le(powerlink::PdoMapEntry{0x6200, 1, 0, 16}.to_u64(), 8)},
  };
  const std::string file = dir.write("cn5.cdc", powerlink::encode_cdc(node_cdc));
  const std::string cfg = (dir.path / "ds1928d.yaml").string();
  const ConfigResult r = from(kHead +
                                  "    - node_id: 5\n      cdc: cn5.cdc\n      preq_size: 4\n"
                                  "      sdo_writes: [{index: 0x2000, u8: 7}]\n",
                              cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  const PowerlinkNodeConfig& n = r.config().powerlink.nodes[0];
  CHECK(n.cdc == file);
  REQUIRE(n.object_writes.size() == 6);
  CHECK(n.object_writes[0] == CnObjectWrite{0x1006, 0, le(1000, 4), true});
  CHECK(n.object_writes[5] == CnObjectWrite{0x2000, 0, {7}, false});
  CHECK(n.pres_size == uint16_t{10});  // 80 bits mapped
  CHECK(n.preq_size == uint16_t{4});   // the YAML wins over the mapping's 2
  const std::string dumped = dump_config(r.config());
  CHECK_THAT(dumped, Catch::Contains("# concise DCF: {index: 0x1a00, subindex: 1"));
  const ConfigResult again = from(dumped, cfg);
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(dump_config(again.config()) == dumped);

  // Broken files: named, with the codec's reason.
  dir.write("short.cdc", {2, 0, 0, 0, 0x06, 0x10, 0, 4, 0, 0, 0, 0xE8, 3, 0, 0, 0x06});
  CHECK_THAT(one_error(kHead + "    - {node_id: 5, cdc: short.cdc}\n", cfg),
             Catch::Contains("powerlink.nodes[0].cdc: " + (dir.path / "short.cdc").string() +
                             " is not a valid concise DCF: entry 1 of 2 is truncated"));
  CHECK_THAT(one_error(kHead + "    - {node_id: 5, cdc: none.cdc}\n", cfg),
             Catch::Contains("powerlink.nodes[0].cdc: no such file: "));
}

TEST_CASE("The MN's mnobd.cdc supplies each node's 0x1F22 objects, identity and sizes",
          "[config][powerlink][cdc]") {
  TempDir dir;
  const std::vector<CdcEntry> cn3 = {{0x1006, 0, le(2000, 4)}, {0x1F98, 4, le(12, 2)}};
  const std::vector<CdcEntry> mn = {
      {0x1006, 0, le(2000, 4)},                 // the MN's own cycle: not for the CN
      {0x1F22, 3, powerlink::encode_cdc(cn3)},  // node 3's objects
      {0x1F84, 3, le(0x000F0191, 4)},           // device type
      {0x1F85, 3, le(0x0000001A, 4)},           // vendor
      {0x1F86, 3, le(0, 4)},                    // 0 = not checked
      {0x1F8D, 3, le(24, 2)},                   // PRes payload limit
      {0x1F26, 3, le(0x3124, 4)},               // expected configuration date
      {0x1F27, 3, le(0, 4)},                    // ... and time: 0, compared as 0
      {0x1F22, 4, {1, 0, 0, 0, 0x06, 0x10}},    // node 4's domain is truncated
  };
  dir.write("mnobd.cdc", powerlink::encode_cdc(mn));
  const std::string cfg = (dir.path / "ds1928d.yaml").string();
  const ConfigResult r = from(kHead + "    - {node_id: 3}\n  cdc: mnobd.cdc\n", cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  const PowerlinkNodeConfig& n = r.config().powerlink.nodes[0];
  REQUIRE(n.object_writes.size() == 2);
  CHECK(n.object_writes[1] == CnObjectWrite{0x1F98, 4, le(12, 2), true});
  CHECK(n.device_type == uint32_t{0x000F0191});
  CHECK(n.vendor_id == uint32_t{0x1A});
  CHECK_FALSE(n.product_code.has_value());
  CHECK(n.pres_size == uint16_t{24});
  CHECK(n.preq_size == uint16_t{12});
  CHECK(n.expected_conf_date == uint32_t{0x3124});
  CHECK_FALSE(n.expected_conf_time.has_value());
  // The YAML's pair wins as a whole over the CDC's.
  const ConfigResult y = from(kHead +
                                  "    - {node_id: 3, expected_conf_time: 0x03735955}\n"
                                  "  cdc: mnobd.cdc\n",
                              cfg);
  INFO(y.error_report());
  REQUIRE(y.ok());
  CHECK_FALSE(y.config().powerlink.nodes[0].expected_conf_date.has_value());
  CHECK(y.config().powerlink.nodes[0].expected_conf_time == uint32_t{0x03735955});
  const std::string dumped = dump_config(y.config());
  CHECK_THAT(dumped, Catch::Contains("expected_conf_time: 0x3735955"));
  const ConfigResult again = from(dumped, cfg);
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(again.config().powerlink.nodes[0].expected_conf_time == uint32_t{0x03735955});
  CHECK_THAT(one_error(kHead + "    - {node_id: 3, expected_conf_date: -1}\n", cfg),
             Catch::Contains("powerlink.nodes[0].expected_conf_date"));
  CHECK_THAT(one_error(kHead + "    - {node_id: 4}\n  cdc: mnobd.cdc\n", cfg),
             Catch::Contains("powerlink.nodes[0].node_id: powerlink.cdc: object 0x1F22/4 (this "
                             "node's concise DCF) is not valid: entry 0 of 1 is truncated"));
}

TEST_CASE("The MN's objects in its mnobd.cdc are the configuration, the YAML overrides each",
          "[config][powerlink][cdc]") {
  TempDir dir;
  // openCONFIGURATOR's MN objects (its Demo_3CN project writes these with 50 ms and 40).
  const std::vector<CdcEntry> mn = {
      {0x1F81, 3, le(0x00000007, 4)},  // NodeAssignment: exists, CN, start it; not mandatory
      {0x1F81, 4, le(0x0000000F, 4)},  // ... node 4 mandatory
      {0x1006, 0, le(500, 4)},         // NMT_CycleLen_U32, µs
      {0x1C02, 3, le(40, 4)},          // DLL_MNCycTimeExceed_REC.Threshold_U32
      {0x1C09, 3, le(40, 4)},          // DLL_MNCNLossPResThreshold_AU32/3
      {0x1F8A, 1, le(2000, 4)},        // WaitSoCPReq_U32, ns
      {0x1F8A, 2, le(50000, 4)},       // AsyncSlotTimeout_U32, ns
      {0x1F89, 1, le(2500, 4)},        // MNWaitNotAct_U32, µs: 2.5 ms
      {0x1F89, 2, le(300000, 4)},      // MNTimeoutPreOp1_U32, µs
      {0x1F92, 3, le(120001, 4)},      // NMT_MNCNPResTimeout_AU32/3, ns: 120.001 µs
      {0x1F92, 4, le(100000, 4)},
  };
  dir.write("mnobd.cdc", powerlink::encode_cdc(mn));
  const std::string cfg = (dir.path / "ds1928d.yaml").string();
  const std::string nodes = "    - {node_id: 3}\n    - {node_id: 4}\n  cdc: mnobd.cdc\n";
  const ConfigResult r = from(kHead + nodes, cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  const DaemonConfig& c = r.config();
  const PowerlinkBusConfig& p = c.powerlink;
  CHECK(c.cycle.period_us == 500);
  CHECK(p.thresholds.cycle_time_exceeded == 40);
  CHECK(p.nodes[0].loss_of_pres_threshold == uint32_t{40});
  CHECK_FALSE(p.nodes[1].loss_of_pres_threshold);  // none for node 4: the network's
  CHECK(p.wait_soc_preq_us == 2);
  CHECK(p.async_timeout_us == 50);
  CHECK(p.nmt.pre_op1_timeout_ms == 300);
  CHECK(p.nmt.wait_not_active_ms == 3);      // rounded up
  CHECK(p.nodes[0].pres_timeout_us == 121);  // rounded up: a timeout is never shortened
  CHECK(p.nodes[1].pres_timeout_us == 100);
  CHECK_FALSE(p.nodes[0].mandatory);
  CHECK(p.nodes[1].mandatory);
  // --print-config says where each came from, and loads back to the same values.
  const std::string dumped = dump_config(c);
  CHECK_THAT(dumped, Catch::Contains("period_us: 500  # cdc 0x1006/0 NMT_CycleLen_U32 = 500 µs "
                                     "(byte 26)"));
  CHECK_THAT(dumped, Catch::Contains("pres_timeout_us: 121  # cdc 0x1F92/3 "
                                     "NMT_MNCNPResTimeout_AU32 = 120001 ns"));
  CHECK_THAT(dumped, Catch::Contains("loss_of_pres_threshold: 40  # cdc 0x1C09/3"));
  CHECK_THAT(dumped, Catch::Contains("loss_of_pres_threshold:   # default"));
  CHECK_THAT(dumped, Catch::Contains("mandatory: false  # cdc 0x1F81/3 NMT_NodeAssignment_AU32 "
                                     "= 0x00000007"));
  CHECK_THAT(dumped, Catch::Contains("async_slot_timeout_us: 50  # cdc 0x1F8A/2"));
  CHECK_THAT(dumped, Catch::Contains("pre_op1_timeout_ms: 300  # cdc 0x1F89/2"));
  CHECK_THAT(dumped, Catch::Contains("wait_not_active_ms: 3  # cdc 0x1F89/1"));
  const ConfigResult again = from(dumped, cfg);
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(again.config().cycle.period_us == 500);
  CHECK(again.config().powerlink.nodes[0].pres_timeout_us == 121);
  CHECK(again.config().powerlink.nodes[0].mandatory == false);

  // The YAML wins where it sets a key, and says so.
  const ConfigResult y = from(
      "bus: powerlink\ncycle:\n  period_us: 1000\npowerlink:\n  interface: veth0\n"
      "  async_slot_timeout_us: 80\n  thresholds: {cycle_time_exceeded: 15}\n  nodes:\n"
      "    - {node_id: 3, pres_timeout_us: 90, loss_of_pres_threshold: 168, mandatory: true}\n"
      "    - {node_id: 4}\n  cdc: mnobd.cdc\n",
      cfg);
  INFO(y.error_report());
  REQUIRE(y.ok());
  CHECK(y.config().cycle.period_us == 1000);
  CHECK(y.config().powerlink.async_timeout_us == 80);
  CHECK(y.config().powerlink.thresholds.cycle_time_exceeded == 15);
  CHECK(y.config().powerlink.nodes[0].pres_timeout_us == 90);
  CHECK(y.config().powerlink.nodes[0].loss_of_pres_threshold == uint32_t{168});
  CHECK(y.config().powerlink.nodes[0].mandatory);
  CHECK(y.config().powerlink.wait_soc_preq_us == 2);  // not set in the YAML: the CDC's
  const std::string ydump = dump_config(y.config());
  CHECK_THAT(ydump, Catch::Contains("period_us: 1000  # yaml"));
  CHECK_THAT(ydump, Catch::Contains("pres_timeout_us: 90  # yaml"));
  CHECK_THAT(ydump, Catch::Contains("wait_soc_preq_us: 2  # cdc 0x1F8A/1"));
  // Without a CDC the dump carries no source comments (nothing to tell apart).
  CHECK_THAT(dump_config(from(kHead + "    - {node_id: 3}\n").config()),
             !Catch::Contains("# default"));
}

TEST_CASE("An MN object out of range or an async-only node in the CDC is refused by name",
          "[config][powerlink][cdc]") {
  TempDir dir;
  const std::string cfg = (dir.path / "ds1928d.yaml").string();
  auto with = [&](std::vector<CdcEntry> mn) {
    dir.write("mnobd.cdc", powerlink::encode_cdc(mn));
    return one_error(kHead + "    - {node_id: 3}\n  cdc: mnobd.cdc\n", cfg);
  };
  // 4-byte count, then entries of 7 header bytes + data: the second entry starts at byte 15.
  CHECK_THAT(with({{0x1F81, 3, le(7, 4)}, {0x1006, 0, le(50, 4)}}),
             Catch::Contains("powerlink.cdc: 0x1006/0 NMT_CycleLen_U32 = 50 µs (byte 15) is "
                             "outside what ds1928d takes for cycle.period_us (100..100000 µs)"));
  CHECK_THAT(with({{0x1F8A, 2, le(100, 4)}}),
             Catch::Contains("powerlink.cdc: 0x1F8A/2 NMT_MNCycleTiming_REC.AsyncSlotTimeout_U32 "
                             "= 100 ns (byte 4) is below DS 301's minimum of 250 ns"));
  CHECK_THAT(with({{0x1F92, 3, le(0, 4)}}),
             Catch::Contains("powerlink.nodes[0].node_id: powerlink.cdc: 0x1F92/3 "
                             "NMT_MNCNPResTimeout_AU32 = 0 ns (byte 4) is below DS 301's minimum"));
  CHECK_THAT(with({{0x1F92, 3, le(200'000'000, 4)}}),
             Catch::Contains("is outside what ds1928d takes for pres_timeout_us (1..100000 µs)"));
  CHECK_THAT(with({{0x1C09, 3, le(40, 2)}, {0x1F81, 3, le(0x107, 4)}}),
             Catch::Contains("powerlink.nodes[0].node_id: powerlink.cdc: 0x1F81/3 "
                             "NMT_NodeAssignment_AU32 marks node 3 async-only (bit 8)"));
  CHECK_THAT(with({{0x1C09, 3, le(40, 8)}}),
             Catch::Contains("0x1C09/3 DLL_MNCNLossPResThreshold_AU32 (byte 4) holds 8 bytes; DS "
                             "301 gives it 4 (UNSIGNED32)"));
}

}  // namespace

TEST_CASE("Timing keys by the standard's names, receive strategy, defaults",
          "[config][powerlink][timing]") {
  const ConfigResult d =
      from("bus: powerlink\npowerlink:\n  interface: eth1\n  nodes:\n    - node_id: 1\n");
  INFO(d.error_report());
  REQUIRE(d.errors().empty());
  const PowerlinkBusConfig& p = d.config().powerlink;
  CHECK(p.nodes[0].pres_timeout_us == 200);
  CHECK_FALSE(p.nodes[0].loss_of_pres_threshold);
  CHECK_FALSE(p.thresholds.loss_of_pres);  // the MN derives it from the period
  CHECK(p.async_timeout_us == 100);
  CHECK(p.wait_soc_preq_us == 0);
  CHECK(p.rx_wait == RxWait::Block);
  CHECK(p.rx_spin_us == 0);

  const ConfigResult r = from(
      "bus: powerlink\npowerlink:\n  interface: eth1\n  rx_wait: spin\n  wait_soc_preq_us: 15\n"
      "  async_slot_timeout_us: 80\n  thresholds: {loss_of_pres: 40}\n  nodes:\n"
      "    - {node_id: 1, pres_timeout_us: 150, loss_of_pres_threshold: 0}\n");
  INFO(r.error_report());
  REQUIRE(r.errors().empty());
  const PowerlinkBusConfig& q = r.config().powerlink;
  CHECK(q.rx_wait == RxWait::Spin);
  CHECK(q.wait_soc_preq_us == 15);
  CHECK(q.async_timeout_us == 80);
  CHECK(q.thresholds.loss_of_pres == 40u);
  CHECK(q.nodes[0].loss_of_pres_threshold == 0u);

  CHECK(one_error("bus: powerlink\npowerlink:\n  interface: eth1\n  rx_wait: poll\n  nodes:\n"
                  "    - node_id: 1\n")
            .find("rx_wait") != std::string::npos);
  CHECK(one_error("bus: powerlink\npowerlink:\n  interface: eth1\n  async_slot_timeout_us: 80\n"
                  "  async_timeout_us: 80\n  nodes:\n    - node_id: 1\n")
            .find("not both") != std::string::npos);
}

TEST_CASE("PollResponse Chaining: prc per node, from the MN's CDC, and what it cannot be",
          "[config][powerlink][prc]") {
  TempDir dir;
  // The MN's CDC: NodeAssignment of node 1 with the PRC bit (0x4000 | exists 0x1 | CN 0x2),
  // node 2 without it; PResActPayloadLimit 0x1F98/5 = 40.
  const std::vector<CdcEntry> mn_cdc = {
      {0x1F81, 1, le(0x4003, 4)},
      {0x1F81, 2, le(0x0003, 4)},
      {0x1F98, 5, le(40, 2)},
  };
  dir.write("mnobd.cdc", powerlink::encode_cdc(mn_cdc));
  const std::string cfg = (dir.path / "ds1928d.yaml").string();
  const std::string head =
      "bus: powerlink\npowerlink:\n  interface: eth1\n  cdc: mnobd.cdc\n  nodes:\n";
  ConfigResult r =
      from(head + "    - node_id: 1\n    - node_id: 2\n    - {node_id: 3, prc: true}\n", cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  CHECK(r.config().powerlink.nodes[0].prc);
  CHECK_FALSE(r.config().powerlink.nodes[1].prc);
  CHECK(r.config().powerlink.nodes[2].prc);
  CHECK(r.config().powerlink.pres_mn_size == 40);
  // The YAML wins over the CDC.
  r = from(head + "    - {node_id: 1, prc: false}\n  pres_mn_size: 0\n", cfg);
  INFO(r.error_report());
  REQUIRE(r.ok());
  CHECK_FALSE(r.config().powerlink.nodes[0].prc);
  CHECK(r.config().powerlink.pres_mn_size == 0);
  CHECK_THAT(dump_config(r.config()), Catch::Contains("prc: false"));
  // A PRC node answers every PResMN: no multiplexed slot.
  CHECK_THAT(one_error("bus: powerlink\npowerlink:\n  interface: eth1\n  nodes:\n"
                       "    - {node_id: 1, prc: true, multiplexed: true}\n"
                       "  multiplex_cycles: 2\n"),
             Catch::Contains("PRC has no multiplexed slots"));
}

TEST_CASE("The PResMN carries the chained nodes' outputs: its size derived and checked",
          "[config][powerlink][prc][timing]") {
  const std::string head =
      "bus: powerlink\ncycle: {period_us: 500}\npowerlink:\n  interface: eth1\n  nodes:\n"
      "    - {node_id: 1, pres_timeout_us: 200, prc: true}\n"
      "    - {node_id: 2, pres_timeout_us: 200, prc: true}\n";
  const std::string axes =
      "axes:\n"
      "  - {name: a, node: 1, slot: 1}\n"
      "  - {name: b, node: 2, slot: 1}\n";
  // Two chained nodes with one module each (OutputSequence | 7 Tx | AckErrorInfo): 18 bytes,
  // node 1 at 0, node 2 at 9. A pres_mn_size below that is refused with the key.
  const std::string e = one_error(head + "  pres_mn_size: 10\n" + axes);
  CHECK_THAT(e, Catch::Contains("powerlink.pres_mn_size"));
  CHECK_THAT(e, Catch::Contains("18 bytes (node 1: 9 bytes at 0, node 2: 9 bytes at 9)"));
  const ConfigResult ok = from(head + "  pres_mn_size: 18\n" + axes);
  INFO(ok.error_report());
  CHECK(ok.errors().empty());
}

TEST_CASE("One multiplexed cycle: multiplex_cycles, slots given or assigned, refusals by key",
          "[config][powerlink][multiplex]") {
  const std::string head = "bus: powerlink\npowerlink:\n  interface: eth1\n";
  ConfigResult r = from(head +
                        "  multiplex_cycles: 4\n  nodes:\n"
                        "    - {node_id: 1}\n"
                        "    - {node_id: 2, multiplex_slot: 3}\n"
                        "    - {node_id: 3, multiplexed: true}\n"
                        "    - {node_id: 4, multiplexed: true}\n");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const auto& n = r.config().powerlink.nodes;
  CHECK(r.config().powerlink.multiplex_cycles == 4);
  CHECK_FALSE(n[0].multiplexed);
  CHECK(n[1].multiplexed);
  CHECK(n[1].multiplex_slot == 3);
  CHECK(n[2].multiplex_slot == 1);  // assigned: the least loaded slots, lowest first
  CHECK(n[3].multiplex_slot == 2);
  CHECK_THAT(dump_config(r.config()), Catch::Contains("multiplex_slot: 2"));
  CHECK_THAT(dump_config(r.config()), Catch::Contains("multiplex_cycles: 4"));
  // A slot outside the multiplexed cycle, a multiplexed node without a count, the old factor.
  CHECK_THAT(
      one_error(head + "  multiplex_cycles: 4\n  nodes:\n    - {node_id: 2, multiplex_slot: 5}\n"),
      Catch::Contains("powerlink.nodes[0].multiplex_slot: slot 5 of node 2 is outside the "
                      "multiplexed cycle of 4"));
  CHECK_THAT(one_error(head + "  nodes:\n    - {node_id: 2, multiplexed: true}\n"),
             Catch::Contains("powerlink.nodes[0].multiplexed: node 2 is multiplexed, but "
                             "powerlink.multiplex_cycles (MultiplCycleCnt) is 0"));
  CHECK_THAT(one_error(head + "  nodes:\n    - {node_id: 2, multiplex: 4}\n"),
             Catch::Contains("per-node multiplex factor is gone"));
}

TEST_CASE("The process image layout and the object scheme per node", "[config][powerlink][pdo]") {
  ConfigResult r = from(kHead +
                        "    - {node_id: 1, layout: packed}\n"
                        "    - {node_id: 2, object_scheme: {input_index: 0x3000}}\n"
                        "  object_scheme: {input_index: 0x2400, output_index: 0x2500}\n");
  INFO(r.error_report());
  REQUIRE(r.ok());
  const PowerlinkBusConfig& p = r.config().powerlink;
  CHECK(p.object_scheme == PdoObjectScheme{0x2400, 0x2500});
  CHECK(p.nodes[0].layout == ImageLayout::kPacked);
  CHECK_FALSE(p.nodes[0].object_scheme);
  CHECK(p.nodes[1].layout == ImageLayout::kAuto);
  // Keys left out come from powerlink.object_scheme.
  CHECK(p.nodes[1].object_scheme == PdoObjectScheme{0x3000, 0x2500});
  const std::string dumped = dump_config(r.config());
  CHECK_THAT(dumped, Catch::Contains("layout: packed"));
  const ConfigResult again = from(dumped);
  INFO(again.error_report());
  REQUIRE(again.ok());
  CHECK(dump_config(again.config()) == dumped);

  // Without a written mapping, `mapping` reads the CN's own at boot; a chained node cannot.
  CHECK(from(kHead + "    - {node_id: 1, layout: mapping}\n").ok());
  CHECK_THAT(one_error(kHead + "    - {node_id: 1, layout: mapping, prc: true}\n"),
             Catch::Contains("powerlink.nodes[0].layout: layout mapping on a PollResponse "
                             "Chaining node (prc) needs the node's TPDO mapping"));
  CHECK_THAT(one_error(kHead + "    - {node_id: 1, layout: fixed}\n"),
             Catch::Contains("powerlink.nodes[0].layout"));
  CHECK_THAT(one_error(kHead + "    - {node_id: 1}\n  object_scheme: {input_index: 0x1000}\n"),
             Catch::Contains("powerlink.object_scheme.input_index"));
}
