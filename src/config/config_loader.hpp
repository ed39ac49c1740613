// Loading and validating the daemon's YAML configuration (docs/configuration.md).
//
// The loader never stops at the first problem: it walks the whole document and returns every
// error it finds, each one naming file, line, column and the full key path, so one run of
// `ds1928d --check-config FILE` shows everything that needs fixing.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "config/config.hpp"

namespace ds1928 {

// Upper bound on configured axes: the cycle, the shared-memory layout and the bus drivers size
// their fixed arrays from it.
inline constexpr std::size_t kMaxAxes = 64;

struct ConfigError {
  std::string file;     // as given to the loader
  int line = 0;         // 1-based; 0 = no position (e.g. the file could not be read)
  int column = 0;       // 1-based
  std::string key;      // full key path, e.g. "axes[1].module.prescaler"; empty = whole document
  std::string message;  // what is wrong and what is allowed

  // "file:line:column: key: message" (parts without a value are left out).
  [[nodiscard]] std::string to_string() const;
};

// Either a complete, validated DaemonConfig or the list of everything that was wrong.
class [[nodiscard]] ConfigResult {
 public:
  explicit ConfigResult(DaemonConfig config) : value_(std::move(config)) {}
  explicit ConfigResult(std::vector<ConfigError> errors) : value_(std::move(errors)) {}

  [[nodiscard]] bool ok() const noexcept { return value_.index() == 0; }
  explicit operator bool() const noexcept { return ok(); }

  // Precondition: ok().
  [[nodiscard]] const DaemonConfig& config() const& { return std::get<DaemonConfig>(value_); }
  [[nodiscard]] DaemonConfig&& config() && { return std::get<DaemonConfig>(std::move(value_)); }

  // Empty when ok().
  [[nodiscard]] const std::vector<ConfigError>& errors() const noexcept;

  // All errors, one per line in document order, each formatted by ConfigError::to_string().
  [[nodiscard]] std::string error_report() const;

 private:
  std::variant<DaemonConfig, std::vector<ConfigError>> value_;
};

// Reads and validates one YAML file. Relative paths inside it (simulated.axes[].encoder_file)
// are resolved against the file's directory.
[[nodiscard]] ConfigResult load_config(const std::string& path);

// Same rules for YAML text already in memory; `name` is used as the file name in messages and
// its directory (if any) as the base of relative paths.
[[nodiscard]] ConfigResult load_config_from_string(std::string_view text,
                                                   const std::string& name = "<string>");

// The effective configuration as YAML in the documented layout, every key written out
// (`ds1928d --check-config` prints it; loading the output gives the same configuration).
[[nodiscard]] std::string dump_config(const DaemonConfig& config);

// Where the control socket goes when the configured directory cannot be created or written
// (daemon started without root and without systemd's RuntimeDirectory): the same file name in
// $XDG_RUNTIME_DIR/ds1928d/, or /tmp/ds1928d-<uid>/ when XDG_RUNTIME_DIR is unset. The daemon
// and ds1928ctl both try the configured path first, then this one.
[[nodiscard]] std::string fallback_socket_path(std::string_view configured_path);

[[nodiscard]] std::string_view to_string(BusKind bus) noexcept;
[[nodiscard]] std::string_view to_string(MotionProfile profile) noexcept;

}  // namespace ds1928
