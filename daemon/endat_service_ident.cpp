#include <spdlog/spdlog.h>

#include "endat/names.hpp"
#include "endat_service_state.hpp"
#include "service/journal.hpp"
#include "x20ds1928/object_dictionary.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Identification: ParamManuf_04..47 through the acyclic registers; else Flatstream reads

void EnDatService::refresh_identification(std::size_t index,
                                          std::function<void(std::error_code)> done) {
  if (index >= axes_.size()) {
    if (done) done(make_error_code(EnDatServiceErrc::no_such_axis));
    return;
  }
  if (done) axes_[index]->ident_waiters.push_back(std::move(done));
  start_identification(index);
}

void EnDatService::start_identification(std::size_t index) {
  Axis& a = *axes_[index];
  if (a.identifying) return;  // the running one answers every waiter
  a.identifying = true;
  a.ident_state = "reading";
  identify_by_registers(index, 0);
}

void EnDatService::identify_by_registers(std::size_t index, unsigned attempt) {
  struct Collect {
    endat::ManufacturerWords words{};
    std::error_code error;
    unsigned remaining = 0;
  };
  auto collect = std::make_shared<Collect>();
  constexpr unsigned kFirst = 4;
  collect->remaining = endat::kManufacturerWords - kFirst;
  for (unsigned w = kFirst; w < endat::kManufacturerWords; ++w) {
    registers_.read(
        static_cast<uint16_t>(index), static_cast<uint16_t>(reg::kParamManuf0 + w), 2,
        [this, index, w, attempt, collect, alive = std::weak_ptr<bool>(alive_)](std::error_code ec,
                                                                                uint32_t v) {
          if (alive.expired()) return;
          if (ec && !collect->error) collect->error = ec;
          collect->words[w] = static_cast<uint16_t>(v);
          if (--collect->remaining != 0) return;
          if (!running_)
            return identification_done(index, make_error_code(EnDatServiceErrc::stopped));
          if (collect->error) {
            spdlog::info(
                "axis {}: identification registers not readable ({}); reading over Flatstream",
                index, collect->error.message());
            return identify_by_flatstream(index);
          }
          auto ident = endat::decode_identification(collect->words);
          if (!ident) {
            // The module may still be reading the encoder after power-up: try again shortly.
            if (attempt < 4) {
              auto timer =
                  std::make_shared<boost::asio::steady_timer>(io_, std::chrono::milliseconds(250));
              timer->async_wait([this, index, attempt, timer, alive = std::weak_ptr<bool>(alive_)](
                                    const boost::system::error_code& e) {
                if (e || alive.expired() || !running_) return;
                identify_by_registers(index, attempt + 1);
              });
              return;
            }
            spdlog::info(
                "axis {}: identification registers inconsistent ({}); reading over Flatstream",
                index, ident.error().message());
            return identify_by_flatstream(index);
          }
          Axis& a = *axes_[index];
          a.words = collect->words;
          a.ident = *ident;
          a.ident_source = "registers";
          identification_done(index, {});
        });
  }
}

void EnDatService::identify_by_flatstream(std::size_t index) {
  std::vector<endat::Request> steps;
  for (unsigned w = 4; w < endat::kManufacturerWords; ++w)
    steps.push_back(
        endat::Request::read(endat::manufacturer_page_mrs(w), static_cast<uint8_t>(w % 16)));
  submit(index, JobKind::Sequence, std::move(steps), [this, index](const JobResult& r) {
    if (r.error) return identification_done(index, r.error);
    endat::ManufacturerWords words{};
    for (const auto& s : r.steps) {
      if (s.error) return identification_done(index, s.error);
      const unsigned global = (s.request.mrs - 0xA1u) / 2u * 16u + s.request.parameter;
      if (global < words.size()) words[global] = s.reply.value();
    }
    auto ident = endat::decode_identification(words);
    if (!ident) return identification_done(index, ident.error());
    Axis& a = *axes_[index];
    a.words = words;
    a.ident = *ident;
    a.ident_source = "flatstream";
    identification_done(index, {});
  });
}

void EnDatService::identification_done(std::size_t index, std::error_code error) {
  Axis& a = *axes_[index];
  a.identifying = false;
  a.ident_error = error;
  if (error) {
    a.ident_state = "failed";
    const std::string cause = cause_source_ ? cause_source_(index) : std::string();
    control::log_event(
        spdlog::level::warn,
        {control::LogEvent::IdentificationFailed, {}, -1, static_cast<int>(index), error.message()},
        fmt::format("axis {}: encoder identification failed: {}{}", index, error.message(),
                    cause.empty() ? std::string() : " (" + cause + ")"));
  } else {
    a.ident_state = "ok";
    spdlog::info("axis {}: EnDat {} {} encoder, {} position bits, ID {}, serial {} (from {})",
                 index, a.ident->command_set == endat::CommandSet::EnDat22 ? "2.2" : "2.1",
                 a.ident->type == endat::EncoderType::Rotary ? "rotary" : "linear",
                 a.ident->position_bits, a.ident->id.to_string(), a.ident->serial.to_string(),
                 a.ident_source);
  }
  if (identified_hook_) identified_hook_(index, error, error ? nullptr : &*a.ident);
  auto waiters = std::move(a.ident_waiters);
  a.ident_waiters.clear();
  for (auto& w : waiters) w(error);
}

bool EnDatService::identifying(std::size_t axis) const {
  return axes_.at(axis)->identifying;
}

}  // namespace ds1928
