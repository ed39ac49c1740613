// The additional-information channels in the shared memory (DS1928_SHM_FEATURE_INFO): a reader of
// the current header sees each channel's name, value, validity and age; the cycle's update rule
// (core/axis_info.hpp) keeps the last valid value when EnDatInfoOK drops.
#include <catch2/catch.hpp>
#include <cstring>
#include <string>
#include <vector>

#include "core/axis_info.hpp"
#include "core/clock.hpp"
#include "ds1928/shm.hpp"
#include "shm_test_util.hpp"

using namespace ds1928;
using namespace ds1928::shm;
using namespace ds1928::shm::test;

TEST_CASE("update_axis_info: OK bits, sign, last valid value and its age", "[info]") {
  AxisInfo info;
  info.configured = 0b0111;
  info.is_signed = 0b0010;
  update_axis_info(info, 0b1111, {3140, 0xFFF6, 0x8000, 77}, 5'000'000);
  CHECK(info.valid == 0b0111);  // channel 4 is not configured: its OK bit is not taken
  CHECK(info.value[0] == 3140);
  CHECK(info.value[1] == -10);     // INT
  CHECK(info.value[2] == 0x8000);  // UINT
  CHECK(info.value[3] == 0);
  CHECK(info.read_ns[3] == 0);
  CHECK(info_age_us(info, 0, 5'000'000) == 0);
  CHECK(info_age_us(info, 0, 7'500'000) == 2500);
  CHECK(info_age_us(info, 3, 7'500'000) == DS1928_INFO_AGE_NEVER);
  // Channel 1's OK bit drops: the value stays, its validity goes, its age grows.
  update_axis_info(info, 0b0110, {9999, 0xFFF5, 1, 0}, 9'000'000);
  CHECK(info.valid == 0b0110);
  CHECK(info.value[0] == 3140);
  CHECK(info.value[1] == -11);
  CHECK(info.value[2] == 1);
  CHECK(info_age_us(info, 0, 9'000'000) == 4000);
  CHECK(info_age_us(info, 1, 9'000'000) == 0);
  CHECK(info_age_us(info, 0, 9'000'000 + (int64_t{1} << 45)) == DS1928_INFO_AGE_NEVER - 1);
}

TEST_CASE("a reader of the current header sees the channels' names, values, validity and age",
          "[info]") {
  const auto name = unique_name("info");
  std::vector<InfoNames> names(2);
  names[0] = {"temperature1", "", "position2_word1", ""};
  names[1] = {std::string(40, 'x'), "", "", "last"};
  Publisher pub;
  REQUIRE_FALSE(pub.open(config_for(name), 2, 1'000'000, names));
  ShmReader reader;
  REQUIRE_FALSE(reader.open(name));
  REQUIRE(reader.has_info());
  CHECK(std::string(reader.info_name(0, 0)) == "temperature1");
  CHECK(reader.info_name(0, 1) == nullptr);
  CHECK(std::string(reader.info_name(0, 2)) == "position2_word1");
  CHECK(std::string(reader.info_name(1, 0)) == std::string(DS1928_INFO_NAME_LEN - 1, 'x'));
  CHECK(std::string(reader.info_name(1, 3)) == "last");
  CHECK(reader.info_name(2, 0) == nullptr);
  CHECK(reader.info_name(0, 4) == nullptr);

  // Before the first publication: no channel has had a value.
  ds1928_axis_data d{};
  ds1928_axis_info info{};
  REQUIRE_FALSE(reader.read(0, d, info));
  CHECK(info.valid == 0);
  CHECK(info.age_us[0] == DS1928_INFO_AGE_NEVER);

  std::vector<AxisStatus> st(2);
  for (uint32_t a = 0; a < 2; ++a) st[a] = status_for(7, a);
  st[0].info.configured = 0b0101;
  st[0].info.is_signed = 0b0100;
  const int64_t read_at = rt::now_ns();
  update_axis_info(st[0].info, 0b0001, {3140, 0, 0xFFFE, 0}, read_at);
  pub.publish(7, st);
  REQUIRE_FALSE(reader.read(0, d, info));
  CHECK(d.cycle == 7);
  CHECK(d.check == ds1928_shm_check(&d));
  CHECK(info.configured == 0b0101);
  CHECK(info.valid == 0b0001);
  CHECK(info.value[0] == 3140);
  CHECK(info.age_us[0] < 60'000'000u);  // published after the read: a small age, never "never"
  CHECK(info.age_us[2] == DS1928_INFO_AGE_NEVER);  // configured, never OK
  // The C function without the C++ wrapper, and an axis out of range.
  ds1928_axis_info c_info{};
  REQUIRE(ds1928_shm_read_axis_info(&reader.header(), 0, &d, &c_info) == 0);
  CHECK(std::memcmp(&c_info, &info, sizeof info) == 0);
  CHECK(ds1928_shm_read_axis_info(&reader.header(), 2, &d, &c_info) == -EINVAL);

  update_axis_info(st[0].info, 0b0100, {1, 0, 0xFFFE, 0}, read_at + 1'000'000);
  pub.publish(8, st);
  REQUIRE_FALSE(reader.read(0, d, info));
  CHECK(info.valid == 0b0100);
  CHECK(info.value[0] == 3140);  // the last valid read
  CHECK(info.value[2] == -2);
  CHECK(info.age_us[0] < 60'000'000u);  // since the first read: still counted
  CHECK(info.age_us[2] == 0);           // read after the publication's clock: never negative
  // Axis 1 has no channels configured.
  REQUIRE_FALSE(reader.read(1, d, info));
  CHECK(info.configured == 0);
  CHECK(info.valid == 0);
}
