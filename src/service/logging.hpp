// The daemon's logging: spdlog, asynchronous (a bounded queue and one writer thread; when the
// queue is full the oldest message is dropped, so no caller ever waits for I/O), to journald
// when systemd started the daemon, to the console otherwise.
//
// The cycle thread still must not log: enqueueing formats and may allocate and lock. It reports
// through counters and lock-free queues; the normal thread logs.
#pragma once

#include <spdlog/spdlog.h>

#include <memory>
#include <optional>
#include <string_view>

namespace ds1928::control {

enum class LogSink { Console, Journald };

// Journald when JOURNAL_STREAM or INVOCATION_ID is set (systemd started us), else console.
[[nodiscard]] LogSink detect_log_sink() noexcept;

// "trace", "debug", "info", "warn"/"warning", "error", "critical", "off".
[[nodiscard]] std::optional<spdlog::level::level_enum> parse_log_level(
    std::string_view text) noexcept;

// Creates the asynchronous logger `name` writing to `sink`, makes it spdlog's default logger
// and returns it. Call once at start-up, before the cycle thread starts.
std::shared_ptr<spdlog::logger> setup_logging(spdlog::level::level_enum level, LogSink sink,
                                              std::string_view name = "ds1928d");

// Flushes and stops the writer thread (at exit).
void shutdown_logging() noexcept;

}  // namespace ds1928::control
