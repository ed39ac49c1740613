#include <cstdio>

#include "endat/names.hpp"
#include "endat_service_state.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Identification and privilege helpers

nlohmann::json identification_json(const endat::Identification& id) {
  char hex[8];
  std::snprintf(hex, sizeof(hex), "0x%04X", id.version_word);
  nlohmann::json j{
      {"endat", id.command_set == endat::CommandSet::EnDat22 ? "2.2" : "2.1"},
      {"version_word", id.version_word},
      {"version_word_hex", hex},
      {"command_set_word", id.command_set_word},
      {"type", id.type == endat::EncoderType::Rotary ? "rotary" : "linear"},
      {"position_bits", id.position_bits},
      {"signal_periods", id.signal_periods},
      {"multiturn", id.multiturn()},
      {"revolutions", id.revolutions},
      {"steps_per_revolution", id.steps_per_revolution},
      {"id", id.id.to_string()},
      {"serial", id.serial.to_string()},
      {"warnings_supported", id.warnings_supported},
      {"checksum", id.checksum},
  };
  return j;
}

nlohmann::json EnDatService::identification_reply(std::size_t axis) const {
  const Axis& a = *axes_.at(axis);
  nlohmann::json j{{"axis", axis}, {"source", a.ident_source}};
  if (a.ident) j["identification"] = identification_json(*a.ident);
  nlohmann::json words = nlohmann::json::object();
  for (unsigned w = 4; w < endat::kManufacturerWords; ++w) {
    char hex[8];
    std::snprintf(hex, sizeof(hex), "0x%04X", a.words[w]);
    nlohmann::json word{{"value", a.words[w]}, {"value_hex", hex}};
    if (const auto name = endat::manufacturer_word_name(w); !name.empty())
      word["name"] = std::string(name);
    words[std::to_string(w)] = std::move(word);
  }
  j["words"] = std::move(words);
  if (a.endat_error) {
    j["endat_error"] = *a.endat_error;
    j["endat_error_names"] = endat::endat_error_names(*a.endat_error);
  }
  if (a.endat_warning) {
    j["endat_warning"] = *a.endat_warning;
    j["endat_warning_names"] = endat::endat_warning_names(*a.endat_warning);
  }
  return j;
}

// ---------------------------------------------------------------------------------------------
// Status

nlohmann::json EnDatService::status_json(std::size_t index) const {
  if (index >= axes_.size()) return nullptr;
  const Axis& a = *axes_[index];
  nlohmann::json id{{"state", a.ident_state}};
  if (!a.ident_source.empty()) id["source"] = a.ident_source;
  if (a.ident_error)
    id["error"] = {{"code", std::string(endat_error_code_name(a.ident_error))},
                   {"message", a.ident_error.message()}};
  if (a.ident) id.update(identification_json(*a.ident));
  nlohmann::json j{{"identification", id}};
  if (a.endat_error) {
    j["endat_error"] = *a.endat_error;
    j["endat_error_names"] = endat::endat_error_names(*a.endat_error);
  }
  if (a.endat_warning) {
    j["endat_warning"] = *a.endat_warning;
    j["endat_warning_names"] = endat::endat_warning_names(*a.endat_warning);
  }
  if (a.status_error) j["status_read_error"] = a.status_error.message();
  const Counters& c = a.counters;
  j["commands"] = {{"queued", a.queue.size()},
                   {"in_flight", a.in_flight.has_value()},
                   {"awaiting_late_reply", a.awaiting_late_reply},
                   {"sent", c.commands_sent},
                   {"replies", c.replies},
                   {"timeouts", c.timeouts},
                   {"resends", c.resends},
                   {"late_replies", c.late_replies},
                   {"unexpected_replies", c.unexpected_replies},
                   {"done", c.jobs_done},
                   {"failed", c.jobs_failed},
                   {"cancelled", c.jobs_cancelled}};
  return j;
}

}  // namespace ds1928
