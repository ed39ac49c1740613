#include "service/logging.hpp"

#include <spdlog/async.h>
#include <spdlog/sinks/stdout_color_sinks.h>

#include <cstdlib>
#include <string>

#include "service/journal.hpp"

namespace ds1928::control {

LogSink detect_log_sink() noexcept {
  const auto set = [](const char* name) {
    const char* v = std::getenv(name);
    return v != nullptr && v[0] != '\0';
  };
  return set("JOURNAL_STREAM") || set("INVOCATION_ID") ? LogSink::Journald : LogSink::Console;
}

std::optional<spdlog::level::level_enum> parse_log_level(std::string_view text) noexcept {
  using spdlog::level::level_enum;
  if (text == "trace") return level_enum::trace;
  if (text == "debug") return level_enum::debug;
  if (text == "info") return level_enum::info;
  if (text == "warn" || text == "warning") return level_enum::warn;
  if (text == "error") return level_enum::err;
  if (text == "critical") return level_enum::critical;
  if (text == "off") return level_enum::off;
  return std::nullopt;
}

std::shared_ptr<spdlog::logger> setup_logging(spdlog::level::level_enum level, LogSink sink,
                                              std::string_view name) {
  // 512 queued messages: the queue's slots are allocated (and, under mlockall, resident) up
  // front at ~400 bytes each (a 250-byte inline buffer per message), so 8192 cost 3.2 MiB. The
  // logger thread drains a burst of 512 in well under a millisecond; beyond that the oldest
  // message is overwritten and counted by spdlog (overrun_oldest), never blocking the caller.
  if (!spdlog::thread_pool()) spdlog::init_thread_pool(512, 1);
  spdlog::sink_ptr out;
  if (sink == LogSink::Journald) {
    // The journal stamps time itself; the sink adds priority, identifier and the records'
    // fields (journal.hpp).
    out = std::make_shared<JournalSink>(std::string(name));
  } else {
    out = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
    out->set_pattern("%Y-%m-%d %H:%M:%S.%e %^%-5l%$ %v");
  }
  auto logger = std::make_shared<spdlog::async_logger>(
      std::string(name), std::move(out), spdlog::thread_pool(),
      spdlog::async_overflow_policy::overrun_oldest);
  set_structured_logging(sink == LogSink::Journald);
  logger->set_level(level);
  logger->flush_on(spdlog::level::warn);
  spdlog::set_default_logger(logger);
  return logger;
}

void shutdown_logging() noexcept {
  try {
    if (auto logger = spdlog::default_logger()) logger->flush();
  } catch (...) {
  }
  spdlog::shutdown();
  set_structured_logging(false);
}

}  // namespace ds1928::control
