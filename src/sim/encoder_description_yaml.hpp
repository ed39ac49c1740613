// Loading an encoder description (docs/endat.md "Encoder description") from YAML: the simulated
// encoder's identification, areas, timing and faults. Keys left out keep the defaults of
// default_encoder_description().
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "sim/endat_encoder.hpp"

namespace ds1928::sim {

struct EncoderLoadResult {
  std::optional<EncoderDescription> description;
  std::string error;  // "file:line:column: key: what" when description is empty
};
[[nodiscard]] EncoderLoadResult load_encoder_description(const std::string& path);
[[nodiscard]] EncoderLoadResult parse_encoder_description(std::string_view yaml,
                                                          std::string_view origin = "<string>");

}  // namespace ds1928::sim
