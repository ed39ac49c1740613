// The encoder description file (docs/endat.md "Encoder description"): YAML into an
// EncoderDescription, every error naming the file, line, column and key.
#include "sim/encoder_description_yaml.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "endat/number.hpp"

namespace ds1928::sim {

using endat::CommandSet;

namespace {

struct LoadError {
  std::string message;
};

std::string where(const YAML::Node& n, std::string_view origin, std::string_view key) {
  std::ostringstream s;
  s << origin;
  const auto m = n.Mark();
  if (!m.is_null()) s << ':' << (m.line + 1) << ':' << (m.column + 1);
  s << ": " << key << ": ";
  return s.str();
}

uint64_t number(const YAML::Node& n, std::string_view origin, std::string_view key, uint64_t max) {
  if (!n.IsScalar()) throw LoadError{where(n, origin, key) + "expected a number"};
  auto r = endat::parse_number(n.Scalar(), 0, max);
  if (!r) throw LoadError{where(n, origin, key) + r.error().message() + " ('" + n.Scalar() + "')"};
  return *r;
}

double real(const YAML::Node& n, std::string_view origin, std::string_view key) {
  try {
    return n.as<double>();
  } catch (const YAML::Exception&) {
    throw LoadError{where(n, origin, key) + "expected a number"};
  }
}

bool boolean(const YAML::Node& n, std::string_view origin, std::string_view key) {
  try {
    return n.as<bool>();
  } catch (const YAML::Exception&) {
    throw LoadError{where(n, origin, key) + "expected true or false"};
  }
}

void only_keys(const YAML::Node& map, std::string_view origin, std::string_view context,
               std::initializer_list<std::string_view> allowed) {
  if (!map.IsMap()) throw LoadError{where(map, origin, context) + "expected a mapping"};
  for (const auto& kv : map) {
    const auto key = kv.first.Scalar();
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) {
      throw LoadError{where(kv.first, origin, std::string(context) + "." + key) + "unknown key"};
    }
  }
}

endat::IdNumber parse_id(const YAML::Node& n, std::string_view origin) {
  const std::string s = n.Scalar();
  const auto dash = s.find('-');
  endat::IdNumber id;
  auto bin = endat::parse_number(s.substr(0, dash), 0, UINT32_MAX);
  if (!bin) throw LoadError{where(n, origin, "id_number") + "expected \"<number>-<2 characters>\""};
  id.binary = static_cast<uint32_t>(*bin);
  if (dash != std::string::npos) {
    const std::string text = s.substr(dash + 1);
    if (text.size() > 2)
      throw LoadError{where(n, origin, "id_number") + "at most 2 characters after '-'"};
    for (std::size_t i = 0; i < text.size(); ++i) id.text[i] = text[i];
  }
  return id;
}

endat::SerialNumber parse_serial(const YAML::Node& n, std::string_view origin) {
  std::string s = n.Scalar();
  endat::SerialNumber sn;
  if (!s.empty() && !std::isdigit(static_cast<unsigned char>(s.front()))) {
    sn.prefix = s.front();
    s.erase(0, 1);
  }
  if (!s.empty() && !std::isdigit(static_cast<unsigned char>(s.back()))) {
    sn.suffix = s.back();
    s.pop_back();
  }
  auto bin = endat::parse_number(s, 0, UINT32_MAX);
  if (!bin) {
    throw LoadError{where(n, origin, "serial_number") +
                    "expected [letter]<decimal number>[letter], e.g. S36845217"};
  }
  sn.binary = static_cast<uint32_t>(*bin);
  return sn;
}

int64_t ms(const YAML::Node& n, std::string_view origin, std::string_view key) {
  const double v = real(n, origin, key);
  if (!(v >= 0.0) || v > 60'000.0) throw LoadError{where(n, origin, key) + "must be 0..60000 ms"};
  return static_cast<int64_t>(std::llround(v * 1e6));
}

EncoderDescription parse(const YAML::Node& root, std::string_view origin) {
  EncoderDescription d = default_encoder_description();
  if (root.IsNull()) return d;
  only_keys(root, origin, "encoder",
            {"endat", "type", "steps_per_revolution", "revolutions", "signal_periods",
             "position_bits", "id_number", "serial_number", "version_word", "warnings_supported",
             "temperature_c", "temperature2_c", "timing_ms", "time_scale", "faults", "areas"});
  if (auto n = root["endat"]) {
    const auto v = n.Scalar();
    if (v == "2.2") {
      d.command_set = CommandSet::EnDat22;
    } else if (v == "2.1") {
      d.command_set = CommandSet::EnDat21;
      d.areas.erase(0xBD);
    } else {
      throw LoadError{where(n, origin, "endat") + "expected 2.1 or 2.2"};
    }
  }
  if (auto n = root["type"]) {
    if (n.Scalar() == "rotary") {
      d.type = endat::EncoderType::Rotary;
    } else if (n.Scalar() == "linear") {
      d.type = endat::EncoderType::Linear;
    } else {
      throw LoadError{where(n, origin, "type") + "expected rotary or linear"};
    }
  }
  if (auto n = root["steps_per_revolution"]) {
    d.steps_per_revolution =
        static_cast<uint32_t>(number(n, origin, "steps_per_revolution", UINT32_MAX));
  }
  if (auto n = root["revolutions"])
    d.revolutions = static_cast<uint16_t>(number(n, origin, "revolutions", 0xFFFF));
  if (auto n = root["signal_periods"]) {
    d.signal_periods = static_cast<uint32_t>(number(n, origin, "signal_periods", UINT32_MAX));
  }
  if (auto n = root["position_bits"]) {
    d.position_bits = static_cast<unsigned>(number(n, origin, "position_bits", 48));
  }
  if (auto n = root["id_number"]) d.id_number = parse_id(n, origin);
  if (auto n = root["serial_number"]) d.serial_number = parse_serial(n, origin);
  if (auto n = root["version_word"])
    d.version_word = static_cast<uint16_t>(number(n, origin, "version_word", 0xFFFF));
  if (auto n = root["warnings_supported"]) {
    d.warnings_supported = static_cast<uint16_t>(number(n, origin, "warnings_supported", 0xFFFF));
  }
  if (auto n = root["temperature_c"]) d.temperature_c = real(n, origin, "temperature_c");
  if (auto n = root["temperature2_c"]) d.temperature2_c = real(n, origin, "temperature2_c");
  if (auto t = root["timing_ms"]) {
    only_keys(t, origin, "timing_ms",
              {"select_memory", "read_parameter", "write_parameter", "reset", "error_reset",
               "select_info"});
    if (auto n = t["select_memory"])
      d.timing.select_memory_ns = ms(n, origin, "timing_ms.select_memory");
    if (auto n = t["read_parameter"])
      d.timing.read_parameter_ns = ms(n, origin, "timing_ms.read_parameter");
    if (auto n = t["write_parameter"])
      d.timing.write_parameter_ns = ms(n, origin, "timing_ms.write_parameter");
    if (auto n = t["reset"]) d.timing.reset_ns = ms(n, origin, "timing_ms.reset");
    if (auto n = t["error_reset"]) d.timing.error_reset_ns = ms(n, origin, "timing_ms.error_reset");
    if (auto n = t["select_info"]) d.timing.select_info_ns = ms(n, origin, "timing_ms.select_info");
  }
  if (auto n = root["time_scale"]) {
    d.timing.scale = real(n, origin, "time_scale");
    if (!(d.timing.scale >= 0.0) || d.timing.scale > 100.0) {
      throw LoadError{where(n, origin, "time_scale") + "must be 0..100"};
    }
  }
  if (auto f = root["faults"]) {
    only_keys(f, origin, "faults",
              {"crc_error_rate", "seed", "position_error", "battery_warning", "battery_error",
               "error_bits", "warning_bits"});
    if (auto n = f["crc_error_rate"]) {
      d.faults.crc_error_rate = real(n, origin, "faults.crc_error_rate");
      if (!(d.faults.crc_error_rate >= 0.0 && d.faults.crc_error_rate <= 1.0)) {
        throw LoadError{where(n, origin, "faults.crc_error_rate") + "must be 0..1"};
      }
    }
    if (auto n = f["seed"])
      d.faults.seed = static_cast<uint32_t>(number(n, origin, "faults.seed", UINT32_MAX));
    if (auto n = f["position_error"])
      d.faults.position_error = boolean(n, origin, "faults.position_error");
    if (auto n = f["battery_warning"])
      d.faults.battery_warning = boolean(n, origin, "faults.battery_warning");
    if (auto n = f["battery_error"])
      d.faults.battery_error = boolean(n, origin, "faults.battery_error");
    if (auto n = f["error_bits"])
      d.faults.error_bits = static_cast<uint16_t>(number(n, origin, "faults.error_bits", 0x7F));
    if (auto n = f["warning_bits"])
      d.faults.warning_bits = static_cast<uint16_t>(number(n, origin, "faults.warning_bits", 0x1F));
  }
  apply_identification(d);
  if (d.type == endat::EncoderType::Rotary) {
    const unsigned needed =
        endat::bits_for(d.steps_per_revolution) + endat::bits_for(d.revolutions);
    if (needed > d.effective_position_bits() || d.effective_position_bits() > 48) {
      throw LoadError{std::string(origin) +
                      ": position_bits: steps_per_revolution × revolutions needs " +
                      std::to_string(needed) + " bits, the encoder has " +
                      std::to_string(d.effective_position_bits()) + " (max 48)"};
    }
  }

  if (auto areas = root["areas"]) {
    if (!areas.IsMap())
      throw LoadError{where(areas, origin, "areas") + "expected a mapping by MRS code"};
    for (const auto& kv : areas) {
      const std::string key = "areas." + kv.first.Scalar();
      const auto mrs = static_cast<uint8_t>(number(kv.first, origin, key, 0xFF));
      if (!endat::is_memory_area_mrs(mrs)) {
        throw LoadError{where(kv.first, origin, key) + "not a memory area MRS code (0xA0..0xBF)"};
      }
      const YAML::Node& a = kv.second;
      only_keys(a, origin, key, {"writable", "blocks", "words_per_block", "words"});
      EncoderArea area = d.areas.count(mrs) ? d.areas[mrs] : make_encoder_area(16, 1, false);
      if (auto n = a["writable"]) area.writable = boolean(n, origin, key + ".writable");
      const auto wpb = a["words_per_block"]
                           ? static_cast<uint8_t>(number(a["words_per_block"], origin,
                                                         key + ".words_per_block", 255))
                           : area.words_per_block;
      const auto blocks =
          a["blocks"] ? static_cast<uint8_t>(number(a["blocks"], origin, key + ".blocks", 255))
                      : area.blocks;
      if (wpb == 0 || blocks == 0)
        throw LoadError{where(a, origin, key) + "blocks and words_per_block must be > 0"};
      if (wpb != area.words_per_block || blocks != area.blocks) {
        area.words.resize(static_cast<std::size_t>(wpb) * blocks, 0);
        area.words_per_block = wpb;
        area.blocks = blocks;
      }
      if (auto w = a["words"]) {
        const std::string wkey = key + ".words";
        if (w.IsSequence()) {
          if (w.size() > area.words.size()) {
            throw LoadError{where(w, origin, wkey) + "more words than the area holds (" +
                            std::to_string(area.words.size()) + ")"};
          }
          for (std::size_t i = 0; i < w.size(); ++i) {
            area.words[i] = static_cast<uint16_t>(number(w[i], origin, wkey, 0xFFFF));
          }
        } else if (w.IsMap()) {
          for (const auto& e : w) {
            const auto idx = number(e.first, origin, wkey, area.words.size() - 1);
            area.words[idx] = static_cast<uint16_t>(number(e.second, origin, wkey, 0xFFFF));
          }
        } else {
          throw LoadError{where(w, origin, wkey) + "expected a list or a mapping word → value"};
        }
      }
      d.areas[mrs] = std::move(area);
    }
  }
  return d;
}

}  // namespace

EncoderLoadResult parse_encoder_description(std::string_view yaml, std::string_view origin) {
  try {
    return {parse(YAML::Load(std::string(yaml)), origin), {}};
  } catch (const LoadError& e) {
    return {std::nullopt, e.message};
  } catch (const YAML::Exception& e) {
    std::ostringstream s;
    s << origin << ':' << (e.mark.line + 1) << ':' << (e.mark.column + 1) << ": " << e.msg;
    return {std::nullopt, s.str()};
  }
}

EncoderLoadResult load_encoder_description(const std::string& path) {
  std::ifstream in(path);
  if (!in) return {std::nullopt, path + ": cannot open"};
  std::stringstream buf;
  buf << in.rdbuf();
  return parse_encoder_description(buf.str(), path);
}

}  // namespace ds1928::sim
