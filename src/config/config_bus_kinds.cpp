// The table of bus kinds (config_bus_kinds.hpp).
#include "config/config_bus_kinds.hpp"

#include <array>

#include "config/config_canio.hpp"
#include "config/config_loader.hpp"
#include "config/config_powerlink.hpp"

namespace ds1928::config_detail {
namespace {

constexpr std::array<BusKindRules, 3> kBusKinds{{
    {BusKind::Simulated, "simulated", "", CycleConfig{}.period_us, std::nullopt, 255, false,
     EmptyAxes::OneDefault, "", nullptr},
    // Node ids 1..239: POWERLINK CNs (240 is the MN). Without axes the MN still runs its CNs
    // (generic CNs, raw process data).
    {BusKind::Powerlink, "powerlink", "POWERLINK", CycleConfig{}.period_us, FunctionModel::Standard,
     239, true, EmptyAxes::Allowed, "interface, nodes", &check_powerlink},
    // SYNC + 3 objects of one module take 920 µs of a 500 kbit/s wire (worst case): the 1 ms
    // default period cannot hold them within canio.max_bus_load; 2 ms can (docs/canio.md).
    {BusKind::Canio, "canio", "CAN-I/O", 2000, FunctionModel::BusController, 255, false,
     EmptyAxes::Refused, "interface, bitrate", &check_canio},
}};
// Row i describes BusKind(i): bus_kind_rules() indexes the table.
static_assert([] {
  for (std::size_t i = 0; i < kBusKinds.size(); ++i)
    if (kBusKinds[i].kind != static_cast<BusKind>(i)) return false;
  return true;
}());

}  // namespace

std::span<const BusKindRules> bus_kinds() noexcept {
  return kBusKinds;
}

const BusKindRules& bus_kind_rules(BusKind kind) noexcept {
  const auto i = static_cast<std::size_t>(kind);
  return kBusKinds[i < kBusKinds.size() ? i : 0];
}

}  // namespace ds1928::config_detail

namespace ds1928 {

std::string_view to_string(BusKind bus) noexcept {
  for (const config_detail::BusKindRules& k : config_detail::bus_kinds())
    if (k.kind == bus) return k.name;
  return "?";
}

}  // namespace ds1928
