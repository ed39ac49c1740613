// The process image from a CN's PDO mapping (powerlink/pdo_image.hpp): entries bound through the
// object scheme, registers read and written at the mapped offsets, bad mappings refused by name.
#include "powerlink/pdo_image.hpp"

#include <array>
#include <catch2/catch.hpp>
#include <random>
#include <vector>

#include "powerlink/frames.hpp"
#include "powerlink/managing_node.hpp"
#include "support/alloc_counter.hpp"

using namespace ds1928;
using namespace ds1928::powerlink;

namespace {

PdoMapEntry entry(uint16_t index, uint8_t sub, unsigned byte_offset, unsigned bytes) {
  return {index, sub, static_cast<uint16_t>(byte_offset * 8), static_cast<uint16_t>(bytes * 8)};
}

// Slot 1's inputs as a rearranged bus controller might map them: PosCycle first, three unmapped
// bytes, PositionLW before PositionHW, no SDCLifeCount, the Rx bytes after another gap.
std::vector<PdoMapEntry> rearranged_tpdo(uint8_t input_mtu) {
  std::vector<PdoMapEntry> t = {
      entry(0x2001, 4, 0, 1),   // PosCycle
      entry(0x2001, 2, 4, 4),   // PositionLW
      entry(0x2001, 1, 8, 4),   // PositionHW
      entry(0x2001, 3, 12, 4),  // PosTime
      entry(0x2001, 6, 16, 1),  // ErrorInfo
      entry(0x2001, 7, 17, 1),  // InputSequence
  };
  for (uint8_t b = 0; b < input_mtu; ++b) t.push_back(entry(0x2001, 8 + b, 20 + b, 1));
  return t;
}
std::vector<PdoMapEntry> rearranged_rpdo(uint8_t output_mtu) {
  std::vector<PdoMapEntry> r = {entry(0x2101, 2, 0, 1), entry(0x2101, 1, 3, 1)};  // Ack, OutSeq
  for (uint8_t b = 0; b < output_mtu; ++b) r.push_back(entry(0x2101, 3 + b, 4 + b, 1));
  return r;
}

std::optional<NodeImageLayout> bind_slot1(const std::vector<PdoMapEntry>& t,
                                          const std::vector<PdoMapEntry>& r, PdoBindIssue& issue,
                                          uint8_t mtu = 7) {
  const ModuleSpec spec{1, mtu, mtu};
  PdoMappingLists lists;
  lists.tpdo = t;
  lists.rpdo = r;
  return bind_pdo_mapping(lists, ObjectScheme{}, std::span<const ModuleSpec>(&spec, 1), issue);
}

}  // namespace

TEST_CASE("A mapping with PosCycle before PositionLW and gaps decodes the exact registers",
          "[powerlink][pdo]") {
  PdoBindIssue issue;
  auto layout = bind_slot1(rearranged_tpdo(7), rearranged_rpdo(7), issue);
  INFO(issue.what);
  REQUIRE(layout);
  CHECK(layout->pres_size == 27);
  CHECK(layout->preq_size == 11);
  // The payload as the CN puts it on the wire, byte by byte (not through our writer).
  std::vector<uint8_t> pres(27, 0xEE);
  pres[0] = 0x85;                            // PosCycle −123
  store_le32(pres.data() + 4, 0x89ABCDEF);   // PositionLW
  store_le32(pres.data() + 8, 0x00000123);   // PositionHW
  store_le32(pres.data() + 12, 0x01020304);  // PosTime
  pres[16] = 0x10;                           // ErrorInfo
  pres[17] = 0x42;                           // InputSequence
  for (int b = 0; b < 7; ++b) pres[20 + b] = static_cast<uint8_t>(0xA0 + b);
  ModuleInputs in;
  REQUIRE(read_inputs(pres, layout->modules[0], in));
  CHECK(in.position_hw == 0x00000123);
  CHECK(in.position_lw == 0x89ABCDEF);
  CHECK(in.pos_time_us == 0x01020304);
  CHECK(in.pos_cycle == -123);
  CHECK(in.sdc_life_count == 0);  // not mapped
  CHECK(in.error_info == 0x10);
  CHECK(in.input_sequence == 0x42);
  for (int b = 0; b < 7; ++b) CHECK(in.rx_bytes[b] == 0xA0 + b);
  // One byte short of the last mapped byte: not decoded.
  CHECK_FALSE(read_inputs(std::span<const uint8_t>(pres.data(), 26), layout->modules[0], in));

  ModuleOutputs out;
  out.output_sequence = 0x33;
  out.ack_error_info = 0x08;
  for (int b = 0; b < 7; ++b) out.tx_bytes[b] = static_cast<uint8_t>(0x50 + b);
  std::vector<uint8_t> preq(11, 0xEE);
  REQUIRE(write_outputs(preq, layout->modules[0], out));
  CHECK(preq[0] == 0x08);
  CHECK(preq[1] == 0xEE);  // the gap is left alone
  CHECK(preq[2] == 0xEE);
  CHECK(preq[3] == 0x33);
  for (int b = 0; b < 7; ++b) CHECK(preq[4 + b] == 0x50 + b);
  CHECK(preq_overlaps(layout->modules[0], 3, 4));
  CHECK_FALSE(preq_overlaps(layout->modules[0], 1, 3));
}

TEST_CASE("The scheme's mapping of the packed layout gives the packed bytes", "[powerlink][pdo]") {
  std::mt19937 rng(7);
  for (int round = 0; round < 50; ++round) {
    const auto mtu = static_cast<uint8_t>(rng() % 28);
    std::vector<ModuleSpec> specs{{1, mtu, mtu}, {3, mtu, mtu}};
    auto packed = make_layout(specs);
    REQUIRE(packed);
    const auto t = tpdo_mapping_of(*packed, ObjectScheme{});
    const auto r = rpdo_mapping_of(*packed, ObjectScheme{});
    PdoBindIssue issue;
    PdoMappingLists lists;
    lists.tpdo = t;
    lists.rpdo = r;
    auto mapped = bind_pdo_mapping(lists, ObjectScheme{}, specs, issue);
    INFO(issue.what);
    REQUIRE(mapped);
    CHECK(mapped->pres_size == packed->pres_size);
    CHECK(mapped->preq_size == packed->preq_size);
    for (std::size_t m = 0; m < 2; ++m) {
      ModuleInputs in;
      in.position_hw = static_cast<uint32_t>(rng());
      in.position_lw = static_cast<uint32_t>(rng());
      in.pos_time_us = static_cast<uint32_t>(rng());
      in.pos_cycle = static_cast<int8_t>(rng());
      in.sdc_life_count = static_cast<int8_t>(rng());
      in.error_info = static_cast<uint8_t>(rng());
      in.input_sequence = static_cast<uint8_t>(rng());
      for (auto& b : in.rx_bytes) b = static_cast<uint8_t>(rng());
      std::vector<uint8_t> a(packed->pres_size), b(packed->pres_size);
      REQUIRE(write_inputs(a, packed->modules[m], in));
      REQUIRE(write_inputs(b, mapped->modules[m], in));
      CHECK(a == b);
      ModuleOutputs out;
      out.output_sequence = static_cast<uint8_t>(rng());
      out.ack_error_info = static_cast<uint8_t>(rng());
      for (auto& x : out.tx_bytes) x = static_cast<uint8_t>(rng());
      std::vector<uint8_t> qa(packed->preq_size), qb(packed->preq_size);
      REQUIRE(write_outputs(qa, packed->modules[m], out));
      REQUIRE(write_outputs(qb, mapped->modules[m], out));
      CHECK(qa == qb);
    }
  }
}

TEST_CASE("A mapping lacking a register or with a bad entry is refused by name",
          "[powerlink][pdo]") {
  PdoBindIssue issue;
  SECTION("missing ErrorInfo: the slot and the register") {
    auto t = rearranged_tpdo(7);
    t.erase(t.begin() + 4);
    CHECK_FALSE(bind_slot1(t, rearranged_rpdo(7), issue));
    CHECK(issue.error == MnError::kPdoRegisterNotMapped);
    CHECK(issue.what == "slot 1: ErrorInfo (0x2001/6) is not mapped");
  }
  SECTION("missing TxByte7") {
    auto r = rearranged_rpdo(7);
    r.pop_back();
    CHECK_FALSE(bind_slot1(rearranged_tpdo(7), r, issue));
    CHECK(issue.what == "slot 1: TxByte7 (0x2101/9) is not mapped");
  }
  SECTION("a register mapped with the wrong length") {
    auto t = rearranged_tpdo(7);
    t[1] = entry(0x2001, 2, 4, 2);
    CHECK_FALSE(bind_slot1(t, rearranged_rpdo(7), issue));
    CHECK(issue.error == MnError::kPdoMappingEntryInvalid);
    CHECK(issue.what == "0x1A00/2 (0x2001/2): length 2 bytes, the register has 4");
  }
  SECTION("a length of no whole bytes") {
    auto t = rearranged_tpdo(7);
    t[0].length_bits = 12;
    CHECK_FALSE(bind_slot1(t, rearranged_rpdo(7), issue));
    CHECK(issue.what == "0x1A00/1 (0x2001/4): length 12 bits is no whole number of bytes");
  }
  SECTION("an entry past the payload") {
    auto t = rearranged_tpdo(7);
    t.push_back(entry(0x6000, 1, 1488, 4));  // not of the scheme, but still checked
    CHECK_FALSE(bind_slot1(t, rearranged_rpdo(7), issue));
    CHECK(issue.what == "0x1A00/14 (0x6000/1): ends at byte 1492, past the 1490-byte payload");
  }
  SECTION("an output register in the TPDO") {
    auto t = rearranged_tpdo(7);
    t.push_back(entry(0x2101, 1, 30, 1));
    CHECK_FALSE(bind_slot1(t, rearranged_rpdo(7), issue));
    CHECK(issue.what == "0x1A00/14 (0x2101/1): an output object mapped into the PRes");
  }
  SECTION("objects outside the scheme are left alone") {
    auto t = rearranged_tpdo(7);
    t.push_back(entry(0x6000, 1, 18, 2));
    CHECK(bind_slot1(t, rearranged_rpdo(7), issue));
  }
}

TEST_CASE("Binding a mapping allocates nothing, a refusal and its message included",
          "[powerlink][pdo][noalloc]") {
  // The MN binds a mapping it read from a CN on the cycle thread (ManagingNode::bind_read_mapping).
  auto missing = rearranged_tpdo(7);
  missing.erase(missing.begin() + 4);  // ErrorInfo
  auto bad_length = rearranged_tpdo(7);
  bad_length[0].length_bits = 12;
  auto past_payload = rearranged_tpdo(7);
  past_payload.push_back(entry(0x6000, 1, 1488, 4));
  const auto good = rearranged_tpdo(7), rpdo = rearranged_rpdo(7);
  std::array<PdoBindIssue, 3> issues{};
  bool bound = false;
  test::HeapCounts counts;
  {
    test::begin_counting();
    bound = bind_slot1(good, rpdo, issues[0]).has_value();
    const bool refused = !bind_slot1(missing, rpdo, issues[0]) &&
                         !bind_slot1(bad_length, rpdo, issues[1]) &&
                         !bind_slot1(past_payload, rpdo, issues[2]);
    counts = test::end_counting();
    CHECK(refused);
  }
  CHECK(bound);
  CHECK(counts.allocations() == 0);
  CHECK(issues[0].what == "slot 1: ErrorInfo (0x2001/6) is not mapped");
  CHECK(issues[1].what == "0x1A00/1 (0x2001/4): length 12 bits is no whole number of bytes");
  CHECK(issues[2].what == "0x1A00/14 (0x6000/1): ends at byte 1492, past the 1490-byte payload");
}

TEST_CASE("A refusal's message is cut at its capacity, never past it", "[powerlink][pdo]") {
  FixedText<8> t;
  t << "slot " << 12345u << ": long";
  CHECK(t == "slot 12");
  CHECK(t.view().size() == 7);
  t.clear();
  t.object(0x1A00, 2);
  CHECK(t == "0x1A00/");
}

TEST_CASE("The MN refuses a node whose written mapping lacks an axis' register, naming it",
          "[powerlink][pdo]") {
  auto u8 = [](uint8_t v) { return std::vector<uint8_t>{v}; };
  auto u64 = [](const PdoMapEntry& e) {
    std::vector<uint8_t> d(8);
    const uint64_t v = e.to_u64();
    for (int i = 0; i < 8; ++i) d[i] = static_cast<uint8_t>(v >> (8 * i));
    return d;
  };
  MnConfig config;
  PowerlinkNodeConfig nc;
  nc.node_id = 4;
  auto t = rearranged_tpdo(7);
  t.erase(t.begin());  // no PosCycle
  nc.object_writes.push_back({0x1A00, 0, u8(0), true});
  for (std::size_t i = 0; i < t.size(); ++i)
    nc.object_writes.push_back({0x1A00, static_cast<uint8_t>(i + 1), u64(t[i]), true});
  nc.object_writes.push_back({0x1A00, 0, u8(static_cast<uint8_t>(t.size())), true});
  config.bus.nodes.push_back(nc);
  AxisConfig a;
  a.node = 4;
  a.slot = 1;
  config.axes.push_back(a);
  try {
    ManagingNode mn(config);
    FAIL("accepted");
  } catch (const std::system_error& e) {
    CHECK(e.code() == MnError::kPdoRegisterNotMapped);
    CHECK(std::string(e.what()).find(
              "process image of node 4, slot 1: PosCycle (0x2001/4) is not mapped") == 0);
  }
  // `layout: packed` keeps the packed image whatever the objects map.
  config.bus.nodes[0].layout = ImageLayout::kPacked;
  ManagingNode packed(config);
  CHECK_FALSE(packed.layout(4)->modules[0].by_fields);
}

TEST_CASE("EnDatInfoOK and EnDatInfo01..04 are read where the mapping puts them, and only there",
          "[powerlink][pdo][info]") {
  auto t = rearranged_tpdo(7);
  t.push_back(entry(0x2001, 0x33, 27, 2));  // EnDatInfo03
  t.push_back(entry(0x2001, 0x30, 29, 1));  // EnDatInfoOK
  t.push_back(entry(0x2001, 0x31, 30, 2));  // EnDatInfo01
  PdoBindIssue issue;
  auto layout = bind_slot1(t, rearranged_rpdo(7), issue);
  INFO(issue.what);
  REQUIRE(layout);
  CHECK(layout->pres_size == 32);
  std::vector<uint8_t> pres(32, 0xEE);
  pres[27] = 0x34;  // EnDatInfo03, little-endian
  pres[28] = 0x12;
  pres[29] = 0x05;  // OK bits of channels 1 and 3
  pres[30] = 0xD5;  // EnDatInfo01 = 3285
  pres[31] = 0x0C;
  ModuleInputs in;
  in.info = {1, 2, 3, 4};
  REQUIRE(read_inputs(pres, layout->modules[0], in));
  CHECK(in.info_ok == 0x05);
  CHECK(in.info[0] == 3285);
  CHECK(in.info[1] == 0);  // not mapped
  CHECK(in.info[2] == 0x1234);
  CHECK(in.info[3] == 0);
  // The simulated CN writes them at the same offsets.
  std::vector<uint8_t> back(32, 0xEE);
  REQUIRE(write_inputs(back, layout->modules[0], in));
  CHECK(std::vector<uint8_t>(back.begin() + 27, back.end()) ==
        std::vector<uint8_t>(pres.begin() + 27, pres.end()));

  // Optional: a mapping without them binds (the packed layout's mapping carries none).
  auto packed = make_layout(std::vector<ModuleSpec>{{1, 7, 7}});
  REQUIRE(packed);
  for (const PdoMapEntry& e : tpdo_mapping_of(*packed, ObjectScheme{}))
    CHECK((e.subindex < 0x30 || e.subindex > 0x34));
  // A word mapped with one byte is refused, naming the entry.
  auto bad = rearranged_tpdo(7);
  bad.push_back(entry(0x2001, 0x32, 27, 1));
  CHECK_FALSE(bind_slot1(bad, rearranged_rpdo(7), issue));
  CHECK(issue.what == "0x1A00/14 (0x2001/50): length 1 bytes, the register has 2");
}
