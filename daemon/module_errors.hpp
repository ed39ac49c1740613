// The error bits of every axis for people and tools (x20ds1928/error_bits.hpp): the words the
// cycle saw (for the status JSON, x20ds1928/error_bits_json.hpp), one journal record per change,
// the metrics' per-bit series. Normal thread only; reads what the cycle thread publishes.
#pragma once

#include <string_view>
#include <vector>

#include "config/config.hpp"
#include "cycle_work.hpp"
#include "metrics/exposition.hpp"
#include "x20ds1928/error_bits.hpp"
#include "x20ds1928/error_bits_json.hpp"

namespace ds1928 {

// The words as the cycle thread last saw them.
[[nodiscard]] ErrorWords error_words(const AxisCounters& c) noexcept;

// Logs one record (LogEvent::ModuleErrorBits) per axis whose bits changed since the last poll.
class ErrorJournal {
 public:
  explicit ErrorJournal(std::size_t axes) : last_(axes) {}
  void poll(const DaemonConfig& config, CycleWork& work, std::string_view bus);

 private:
  std::vector<ErrorWords> last_;
};

// ds1928_axis_module_error{axis, name, register, bit, class}: 1 while the bit is set, for every
// bit of the table.
void append_module_error_metrics(metrics::Exposition& out, const DaemonConfig& config,
                                 CycleWork& work);

}  // namespace ds1928
