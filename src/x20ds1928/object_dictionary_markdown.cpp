// docs/registers.md's table, rendered from the object dictionary (checked by
// x20ds1928_object_dictionary_test; `ds1928-registers` prints it).
#include <cstdio>

#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {
namespace {

using D = RegisterDirection;

[[nodiscard]] std::string hex2(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%02X", v);
  return buf;
}

[[nodiscard]] std::string numbers(const RegisterInfo& r) {
  std::string out = std::to_string(r.number);
  if (r.count > 1) {
    out += "..";
    out += std::to_string(r.last());
    if (r.stride > 1) out += " step " + std::to_string(r.stride);
  }
  return out;
}

// Access under one function model: the direction, the members it has there, or "—".
[[nodiscard]] std::string access(const RegisterInfo& r, FunctionModel fm) {
  if (!r.in_model(fm)) return "—";
  std::string out(to_string(r.direction));
  if (r.count > 1 && r.members(fm) != r.count) out += " (" + std::to_string(r.members(fm)) + ")";
  const ValueRange v = r.accepts(fm);
  if (r.range || r.fm254_range) {
    out += ": " + std::to_string(v.min);
    if (v.max != v.min) out += "–" + std::to_string(v.max);
  }
  return out;
}

[[nodiscard]] std::string fm0_offset(const RegisterInfo& r) {
  if (r.fm0_offset == kNoOffset || !(r.models & kFm0)) return "—";
  return std::string(r.direction == D::In ? "PRes " : "PReq ") + std::to_string(r.fm0_offset) +
         (r.fm0_after_tx_bytes ? " + OutputMTU" : "");
}

[[nodiscard]] std::string can_offset(const RegisterInfo& r) {
  if (r.can_offset == kNoOffset) return "—";
  const int last = r.can_offset + r.members(FunctionModel::BusController) * r.size() - 1;
  std::string span = std::to_string(r.can_offset);
  if (last != r.can_offset) span += "–" + std::to_string(last);
  if (r.direction == D::In)
    return "in " + span + " (object " + std::to_string(r.can_offset / 8 + 1) + ")";
  return "out " + span;
}

[[nodiscard]] std::string sdo(const RegisterInfo& r) {
  if (r.sdo_subindex == 0) return "—";
  std::string out = hex2(r.sdo_subindex);
  if (r.count > 1) out += "–" + hex2(r.sdo_subindex + r.count - 1U);
  return out;
}

}  // namespace

std::string object_dictionary_markdown() {
  std::string out =
      "| register | name | type | FM0 | FM254 | default | FM0 block offset | FM254 CAN offset | "
      "SDO subindex | setting | start-up order |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const RegisterInfo& r : kObjectDictionary) {
    out += "| " + numbers(r) + " | " + std::string(r.name) + (r.view ? " (view)" : "") + " | " +
           std::string(to_string(r.type)) + " | " + access(r, FunctionModel::Standard) + " | " +
           access(r, FunctionModel::BusController) + " | " +
           (r.default_value ? std::to_string(*r.default_value) : std::string("—")) + " | " +
           fm0_offset(r) + " | " + can_offset(r) + " | " + sdo(r) + " | " +
           std::string(setting_key(r.setting)) + " | " +
           (r.startup_order ? std::to_string(r.startup_order) : std::string("—")) + " |\n";
  }
  return out;
}

}  // namespace ds1928
