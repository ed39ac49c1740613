// Writer of the Prometheus text exposition format (version 0.0.4) and of OpenMetrics 1.0.0:
// families with HELP/TYPE (and UNIT in OpenMetrics), samples with escaped label values,
// histograms with cumulative buckets, `# EOF` at the end of OpenMetrics. Pure: builds a string.
//
// A family's samples follow its header without interruption (both formats require it): callers
// open a family, write all its samples, then open the next.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <span>
#include <string>
#include <string_view>

namespace ds1928::metrics {

enum class Format : uint8_t {
  Prometheus,   // text/plain; version=0.0.4
  OpenMetrics,  // application/openmetrics-text; version=1.0.0
};

[[nodiscard]] std::string_view content_type(Format f) noexcept;

enum class Type : uint8_t { Counter, Gauge, Histogram, Info };

struct Label {
  std::string_view name;
  std::string_view value;
};
using Labels = std::initializer_list<Label>;

class Exposition {
 public:
  explicit Exposition(Format format) : format_(format) {}

  // Opens a family. `name` is the family name by Prometheus conventions without the sample
  // suffixes the type adds: a counter "ds1928_cycles" is exposed as ds1928_cycles_total, an info
  // "ds1928_build" as ds1928_build_info. A name ending in "_seconds" etc. gets `unit` in
  // OpenMetrics' # UNIT line.
  void family(std::string_view name, Type type, std::string_view help, std::string_view unit = {});

  // A counter, gauge or info sample of the open family.
  void sample(Labels labels, uint64_t value);
  void sample(Labels labels, double value);
  void sample(uint64_t value) { sample({}, value); }

  // A histogram sample set of the open family: `upper` are the bucket bounds (ascending, in the
  // family's unit), `counts` the samples in each bucket alone (not cumulative), one more than
  // `upper` (the +Inf bucket last), `sum` the sum of all samples in the family's unit.
  void histogram(Labels labels, std::span<const double> upper, std::span<const uint64_t> counts,
                 double sum);

  // The text; OpenMetrics ends with "# EOF". The writer is spent afterwards.
  [[nodiscard]] std::string finish();

 private:
  void series_name(std::string_view suffix);
  void labels(Labels labels, std::string_view le = {});

  Format format_;
  Type type_ = Type::Gauge;
  std::string name_;
  std::string out_;
};

// Label value escaping of both formats: backslash, double quote and line feed.
void append_escaped(std::string& out, std::string_view value);

}  // namespace ds1928::metrics
