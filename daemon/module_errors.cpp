#include "module_errors.hpp"

#include <fmt/format.h>

#include "service/journal.hpp"

namespace ds1928 {
namespace {

std::string names(const ErrorWords& w) {
  std::string out;
  for (const SetErrorBit& b : set_error_bits(w)) {
    if (!out.empty()) out += ',';
    out += b.label();
  }
  return out.empty() ? "none" : out;
}

}  // namespace

ErrorWords error_words(const AxisCounters& c) noexcept {
  return {c.error_info.load(std::memory_order_relaxed),
          static_cast<uint16_t>(c.endat_error.load(std::memory_order_relaxed)),
          static_cast<uint16_t>(c.endat_warning.load(std::memory_order_relaxed))};
}

void ErrorJournal::poll(const DaemonConfig& config, CycleWork& work, std::string_view bus) {
  for (std::size_t i = 0; i < last_.size() && i < work.axis_count(); ++i) {
    const ErrorWords now = error_words(work.counters(i));
    const ErrorWords before = last_[i];
    if (now == before) continue;
    last_[i] = now;
    const ErrorWords came{static_cast<uint8_t>(now.error_info & ~before.error_info),
                          static_cast<uint16_t>(now.endat_error & ~before.endat_error),
                          static_cast<uint16_t>(now.endat_warning & ~before.endat_warning)};
    const ErrorWords went{static_cast<uint8_t>(before.error_info & ~now.error_info),
                          static_cast<uint16_t>(before.endat_error & ~now.endat_error),
                          static_cast<uint16_t>(before.endat_warning & ~now.endat_warning)};
    const ErrorAssessment a = assess(config.axes[i].error_policy(), now);
    const std::string set = names(now);
    const auto level = a.fault     ? spdlog::level::err
                       : a.warning ? spdlog::level::warn
                                   : spdlog::level::info;
    control::log_event(
        level, {control::LogEvent::ModuleErrorBits, bus, -1, static_cast<int>(i), set},
        fmt::format("axis {} ({}): error bits {} (came: {}; went: {})", i, config.axes[i].name, set,
                    came == ErrorWords{} ? "none" : names(came),
                    went == ErrorWords{} ? "none" : names(went)));
  }
}

void append_module_error_metrics(metrics::Exposition& out, const DaemonConfig& config,
                                 CycleWork& work) {
  out.family("ds1928_axis_module_error", metrics::Type::Gauge,
             "1 while the bit of the module's ErrorInfo, EnDatError or EnDatWarning register is "
             "set (docs/registers.md, error bits).");
  for (std::size_t i = 0; i < config.axes.size() && i < work.axis_count(); ++i) {
    const ErrorWords w = error_words(work.counters(i));
    const std::string axis = std::to_string(i);
    for (const ErrorBit& b : error_bits())
      out.sample({{"axis", axis},
                  {"name", config.axes[i].name},
                  {"register", to_string(b.reg)},
                  {"bit", b.name},
                  {"class", to_string(b.cls)}},
                 uint64_t{(w[b.reg] & (1u << b.bit)) != 0 ? 1u : 0u});
  }
}

}  // namespace ds1928
