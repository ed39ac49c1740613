#include "error_bits_text.hpp"

#include <iostream>
#include <string>

namespace ds1928::ctl {

nlohmann::json error_bits_json(const ErrorWords& words) {
  nlohmann::json out = nlohmann::json::array();
  for (const SetErrorBit& b : set_error_bits(words)) {
    nlohmann::json j{
        {"register", std::string(to_string(b.reg))}, {"bit", b.bit}, {"name", b.label()}};
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

void print_error_bits(const nlohmann::json& bits) {
  if (!bits.is_array()) return;
  for (const auto& b : bits) {
    std::cout << "        " << b.value("name", std::string("?")) << " ("
              << b.value("class", std::string("?"));
    if (b.contains("effect")) std::cout << ", " << b.value("effect", std::string());
    std::cout << ")";
    if (b.contains("meaning")) std::cout << ": " << b.value("meaning", std::string());
    if (b.contains("remedy")) std::cout << " — " << b.value("remedy", std::string());
    std::cout << "\n";
  }
}

}  // namespace ds1928::ctl
