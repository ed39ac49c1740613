#include "config/config_sdo_objects.hpp"

#include <string>

#include "x20ds1928/object_dictionary.hpp"

namespace ds1928::config_detail {

void parse_sdo_objects(Section& s, std::string_view key,
                       std::map<uint16_t, std::pair<uint16_t, uint8_t>>& out) {
  std::map<uint16_t, Loc> seen;
  for (auto& item : s.list(key)) {
    Section o(s.diag(), item.node, item.path, item.at);
    for (const char* required : {"register", "index"}) {
      if (!o.has(required)) s.diag().error(item.at, o.child(required), "missing required key");
    }
    uint16_t reg = 0;
    uint16_t index = 0;
    uint8_t subindex = 0;
    const bool have_reg = o.integer("register", reg, 0, kU16, "(X20DS1928 register number)");
    const bool have_index = o.integer("index", index, 1, kU16);
    const bool subindex_ok = !o.has("subindex") || o.integer("subindex", subindex, 0, kU8);
    if (have_reg && !find_register(reg)) {
      o.error("register",
              std::to_string(reg) + " is not an X20DS1928 register (docs/registers.md)");
    } else if (have_reg) {
      if (const auto [it, fresh] = seen.emplace(reg, o.value_at("register")); !fresh) {
        o.error("register", "register " + std::to_string(reg) + " is mapped twice (also at " +
                                where(it->second) + ")");
      } else if (have_index && subindex_ok) {
        out[reg] = {index, subindex};
      }
    }
    o.finish();
  }
}

}  // namespace ds1928::config_detail
