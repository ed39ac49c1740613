// Concise DCF codec: the documented layout byte by byte, round trips of random object lists,
// and precise errors for every truncation and for garbage.
#include <catch2/catch.hpp>
#include <random>

#include "powerlink/concise_dcf.hpp"

namespace ds1928::powerlink {
namespace {

TEST_CASE("A concise DCF decodes field by field as EPSG DS 301 lays it out", "[powerlink][cdc]") {
  // Two entries: 0x1006/0 = 1000 µs (u32) and 0x1F98/5 = 36 (u16), little endian.
  const std::vector<uint8_t> file = {
      0x02, 0x00, 0x00, 0x00,                    // 2 entries
      0x06, 0x10, 0x00, 0x04, 0x00, 0x00, 0x00,  // 0x1006/0, 4 bytes
      0xE8, 0x03, 0x00, 0x00,                    // 1000
      0x98, 0x1F, 0x05, 0x02, 0x00, 0x00, 0x00,  // 0x1F98/5, 2 bytes
      0x24, 0x00,                                // 36
  };
  const CdcDecodeResult r = decode_cdc(file);
  REQUIRE(r.ok());
  REQUIRE(r.entries.size() == 2);
  CHECK(r.entries[0].index == 0x1006);
  CHECK(r.entries[0].subindex == 0);
  CHECK(r.entries[0].as_unsigned() == uint64_t{1000});
  CHECK(r.entries[1].index == 0x1F98);
  CHECK(r.entries[1].subindex == 5);
  CHECK(r.entries[1].data == std::vector<uint8_t>{0x24, 0x00});
  CHECK(encode_cdc(r.entries) == file);
  const ImageSizes sizes = image_sizes_from_objects(r.entries);
  CHECK(sizes.pres_size == uint16_t{36});
  CHECK_FALSE(sizes.preq_size.has_value());
}

TEST_CASE("PDO mapping entries give the payload size, 0x1F98 limits take precedence",
          "[powerlink][cdc]") {
  auto u64 = [](uint64_t v) {
    std::vector<uint8_t> d;
    for (int i = 0; i < 8; ++i) d.push_back(static_cast<uint8_t>(v >> (8 * i)));
    return d;
  };
  // 0x1A00: 0x6000/1 8 bits at bit 0, 0x6401/2 16 bits at bit 32 → 6 bytes.
  const PdoMapEntry a{0x6000, 1, 0, 8};
  const PdoMapEntry b{0x6401, 2, 32, 16};
  CHECK(PdoMapEntry::from_u64(0x0010'0020'0002'6401ULL).offset_bits == 32);
  CHECK(b.to_u64() == 0x0010'0020'0002'6401ULL);
  std::vector<CdcEntry> objects = {
      {obj::kTxPdoMapping, 0, {2}},
      {obj::kTxPdoMapping, 1, u64(a.to_u64())},
      {obj::kTxPdoMapping, 2, u64(b.to_u64())},
      {obj::kTxPdoMapping, 3, u64(PdoMapEntry{0x6000, 9, 64, 64}.to_u64())},
      {obj::kRxPdoMapping, 0, {1}},
      {obj::kRxPdoMapping, 1, u64(PdoMapEntry{0x6200, 1, 0, 12}.to_u64())}};
  ImageSizes s = image_sizes_from_objects(objects);
  CHECK(s.pres_size == uint16_t{6});  // entry 3 is beyond the count: not mapped
  CHECK(s.preq_size == uint16_t{2});  // 12 bits round up
  // Written in order: disabled, entries, enabled — the last value of sub 0 counts.
  objects.insert(objects.begin(), {obj::kTxPdoMapping, 0, {0}});
  CHECK(image_sizes_from_objects(objects).pres_size == uint16_t{6});
  objects.push_back({obj::kTxPdoMapping, 0, {1}});
  CHECK(image_sizes_from_objects(objects).pres_size == uint16_t{1});
  objects.push_back({obj::kCycleTiming, 4, {40, 0}});
  s = image_sizes_from_objects(objects);
  CHECK(s.preq_size == uint16_t{40});
}

TEST_CASE("Truncated and garbage concise DCFs are refused with the place and the reason",
          "[powerlink][cdc]") {
  const std::vector<CdcEntry> entries = {{0x1006, 0, {0xE8, 0x03, 0, 0}},
                                         {0x1C14, 0, {1, 2, 3, 4}}};
  const std::vector<uint8_t> good = encode_cdc(entries);
  CHECK_THAT(decode_cdc(std::span(good).first(3)).error->message,
             Catch::Contains("is 3 bytes long; a concise DCF starts with a 4-byte entry count"));
  CHECK_THAT(decode_cdc(std::vector<uint8_t>{0, 0, 0, 0}).error->message,
             Catch::Contains("no entries"));
  // Cut inside the second entry's data.
  auto cut = decode_cdc(std::span(good).first(good.size() - 2));
  REQUIRE_FALSE(cut.ok());
  CHECK(cut.error->entry == 1);
  CHECK_THAT(
      cut.error->message,
      Catch::Equals(
          "entry 1 (0x1C14/0 DLL_CNLossOfSocTolerance_U32) announces 4 data bytes, only 2 remain"));
  CHECK(cut.entries.size() == 1);
  // Cut inside the second entry's header.
  cut = decode_cdc(std::span(good).first(4 + 11 + 3));
  CHECK_THAT(cut.error->message, Catch::Contains("entry 1 of 2 is truncated"));
  // Bytes after the last entry.
  auto longer = good;
  longer.push_back(0);
  CHECK_THAT(decode_cdc(longer).error->message,
             Catch::Equals("1 bytes follow the last of the 2 announced entries"));
  // A text file is no concise DCF: its "count" is absurd.
  const std::string text = "index,subindex,value\n0x1006,0,1000\n";
  CHECK_THAT(decode_cdc(std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()))
                 .error->message,
             Catch::Contains("not a concise DCF"));
}

TEST_CASE("Random object lists round-trip, every prefix and random bytes decode or fail cleanly",
          "[powerlink][cdc][fuzz]") {
  std::mt19937 rng(1928);
  for (int round = 0; round < 300; ++round) {
    std::vector<CdcEntry> entries(1 + rng() % 12);
    for (auto& e : entries) {
      e.index = static_cast<uint16_t>(rng());
      e.subindex = static_cast<uint8_t>(rng());
      e.data.resize(rng() % 40);
      for (auto& b : e.data) b = static_cast<uint8_t>(rng());
    }
    const auto bytes = encode_cdc(entries);
    const auto back = decode_cdc(bytes);
    REQUIRE(back.ok());
    REQUIRE(back.entries == entries);
    // Every strict prefix is an error, never a crash or a silent success.
    const std::size_t cut = rng() % bytes.size();
    const auto partial = decode_cdc(std::span(bytes).first(cut));
    REQUIRE_FALSE(partial.ok());
    CHECK(partial.error->offset <= cut);
    CHECK(partial.entries.size() <= entries.size());
    // Random bytes: whatever comes out is consistent with the input length.
    std::vector<uint8_t> noise(rng() % 64);
    for (auto& b : noise) b = static_cast<uint8_t>(rng());
    const auto n = decode_cdc(noise);
    if (n.ok()) CHECK(encode_cdc(n.entries) == noise);
  }
}

}  // namespace
}  // namespace ds1928::powerlink
