#include "x20ds1928/error_bits_json.hpp"

#include <string>

namespace ds1928 {
namespace {

std::string_view effect_name(const ErrorPolicy& p, ErrorRegister reg, unsigned bit) noexcept {
  const auto r = static_cast<std::size_t>(reg);
  const auto m = static_cast<uint16_t>(1u << bit);
  if ((p.invalidate[r] & m) != 0) return "module_error";
  if ((p.hold[r] & m) != 0) return "hold";
  return "flag";
}

nlohmann::json bits_json(const ErrorWords& words, const ErrorPolicy* policy) {
  nlohmann::json out = nlohmann::json::array();
  for (const SetErrorBit& b : set_error_bits(words)) {
    nlohmann::json j{
        {"register", std::string(to_string(b.reg))}, {"bit", b.bit}, {"name", b.label()}};
    if (policy != nullptr) j["effect"] = std::string(effect_name(*policy, b.reg, b.bit));
    if (b.info != nullptr) {
      j["class"] = std::string(to_string(b.info->cls));
      j["meaning"] = std::string(b.info->meaning);
      j["remedy"] = std::string(b.info->remedy);
    } else {
      j["class"] = "reserved";
    }
    out.push_back(std::move(j));
  }
  return out;
}

}  // namespace

nlohmann::json error_bits_json(const ErrorWords& words) {
  return bits_json(words, nullptr);
}

nlohmann::json error_bits_json(const ErrorWords& words, const ErrorPolicy& policy) {
  return bits_json(words, &policy);
}

}  // namespace ds1928
