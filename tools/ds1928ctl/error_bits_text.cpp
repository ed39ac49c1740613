#include "error_bits_text.hpp"

#include <iostream>
#include <string>

namespace ds1928::ctl {

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
