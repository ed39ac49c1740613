#include "metrics/exposition.hpp"

#include <fmt/format.h>

#include <cmath>
#include <iterator>

namespace ds1928::metrics {

std::string_view content_type(Format f) noexcept {
  return f == Format::OpenMetrics ? "application/openmetrics-text; version=1.0.0; charset=utf-8"
                                  : "text/plain; version=0.0.4; charset=utf-8";
}

void append_escaped(std::string& out, std::string_view value) {
  for (char c : value) {
    switch (c) {
      case '\\':
        out += "\\\\";
        break;
      case '"':
        out += "\\\"";
        break;
      case '\n':
        out += "\\n";
        break;
      default:
        out += c;
    }
  }
}

namespace {

// HELP text: backslash and line feed escaped (0.0.4); OpenMetrics also escapes the quote.
void append_help(std::string& out, std::string_view help, Format f) {
  for (char c : help) {
    if (c == '\\')
      out += "\\\\";
    else if (c == '\n')
      out += "\\n";
    else if (c == '"' && f == Format::OpenMetrics)
      out += "\\\"";
    else
      out += c;
  }
}

std::string_view type_name(Type t, Format f) noexcept {
  switch (t) {
    case Type::Counter:
      return "counter";
    case Type::Gauge:
      return "gauge";
    case Type::Histogram:
      return "histogram";
    case Type::Info:
      return f == Format::OpenMetrics ? "info" : "gauge";
  }
  return "unknown";
}

// Shortest text that reads back as the same double; infinities and NaN as both formats spell
// them.
void append_number(std::string& out, double v) {
  if (std::isnan(v))
    out += "NaN";
  else if (std::isinf(v))
    out += v > 0 ? "+Inf" : "-Inf";
  else
    fmt::format_to(std::back_inserter(out), "{}", v);
}

}  // namespace

void Exposition::family(std::string_view name, Type type, std::string_view help,
                        std::string_view unit) {
  type_ = type;
  name_.assign(name);
  // 0.0.4 names the family as its samples are named (counters with _total, info as _info);
  // OpenMetrics names the family without those suffixes.
  std::string header_name(name);
  if (format_ == Format::Prometheus) {
    if (type == Type::Counter) header_name += "_total";
    if (type == Type::Info) header_name += "_info";
  }
  out_ += "# HELP ";
  out_ += header_name;
  out_ += ' ';
  append_help(out_, help, format_);
  out_ += "\n# TYPE ";
  out_ += header_name;
  out_ += ' ';
  out_ += type_name(type, format_);
  out_ += '\n';
  if (format_ == Format::OpenMetrics && !unit.empty()) {
    out_ += "# UNIT ";
    out_ += header_name;
    out_ += ' ';
    out_ += unit;
    out_ += '\n';
  }
}

void Exposition::series_name(std::string_view suffix) {
  out_ += name_;
  out_ += suffix;
}

void Exposition::labels(Labels labels, std::string_view le) {
  if (labels.size() == 0 && le.empty()) return;
  out_ += '{';
  bool first = true;
  for (const Label& l : labels) {
    if (!first) out_ += ',';
    first = false;
    out_ += l.name;
    out_ += "=\"";
    append_escaped(out_, l.value);
    out_ += '"';
  }
  if (!le.empty()) {
    if (!first) out_ += ',';
    out_ += "le=\"";
    out_ += le;
    out_ += '"';
  }
  out_ += '}';
}

void Exposition::sample(Labels l, uint64_t value) {
  series_name(type_ == Type::Counter ? "_total" : type_ == Type::Info ? "_info" : "");
  labels(l);
  fmt::format_to(std::back_inserter(out_), " {}\n", value);
}

void Exposition::sample(Labels l, double value) {
  series_name(type_ == Type::Counter ? "_total" : type_ == Type::Info ? "_info" : "");
  labels(l);
  out_ += ' ';
  append_number(out_, value);
  out_ += '\n';
}

void Exposition::histogram(Labels l, std::span<const double> upper,
                           std::span<const uint64_t> counts, double sum) {
  uint64_t cumulative = 0;
  std::string le;
  for (std::size_t i = 0; i < counts.size(); ++i) {
    cumulative += counts[i];
    le.clear();
    if (i < upper.size())
      append_number(le, upper[i]);
    else
      le = "+Inf";
    series_name("_bucket");
    labels(l, le);
    fmt::format_to(std::back_inserter(out_), " {}\n", cumulative);
  }
  series_name("_count");
  labels(l);
  fmt::format_to(std::back_inserter(out_), " {}\n", cumulative);
  series_name("_sum");
  labels(l);
  out_ += ' ';
  append_number(out_, sum);
  out_ += '\n';
}

std::string Exposition::finish() {
  if (format_ == Format::OpenMetrics) out_ += "# EOF\n";
  return std::move(out_);
}

}  // namespace ds1928::metrics
