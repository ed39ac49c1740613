// C++ owner of a shared-memory mapping (shm.h): closes it on destruction, reports errors as
// std::error_code. Header-only; needs nothing but the C header.
#pragma once

#include <cstdint>
#include <string>
#include <system_error>
#include <utility>

#include "ds1928/shm.h"

namespace ds1928 {

enum class ShmWait { Published, Timeout, Stopped };

class ShmReader {
 public:
  ShmReader() noexcept = default;
  ~ShmReader() { close(); }
  ShmReader(ShmReader&& other) noexcept
      : reader_(std::exchange(other.reader_, {})), name_(std::move(other.name_)) {}
  ShmReader& operator=(ShmReader&& other) noexcept {
    if (this != &other) {
      close();
      reader_ = std::exchange(other.reader_, {});
      name_ = std::move(other.name_);
    }
    return *this;
  }
  ShmReader(const ShmReader&) = delete;
  ShmReader& operator=(const ShmReader&) = delete;

  // errc::no_such_file_or_directory: no daemon; resource_unavailable_try_again: still being
  // created; protocol_error: not a ds1928d object or another ABI version.
  [[nodiscard]] std::error_code open(std::string name) {
    close();
    if (const int rc = ds1928_shm_reader_open(&reader_, name.c_str()); rc != 0)
      return {-rc, std::generic_category()};
    name_ = std::move(name);
    return {};
  }
  void close() noexcept { ds1928_shm_reader_close(&reader_); }

  // Maps the name again when the daemon behind the current mapping looks dead or stopped.
  // True when a new daemon generation is mapped now.
  [[nodiscard]] bool reopen() noexcept {
    return ds1928_shm_reader_reopen(&reader_, name_.c_str()) == 1;
  }

  [[nodiscard]] bool is_open() const noexcept { return reader_.header != nullptr; }
  [[nodiscard]] bool can_wait() const noexcept { return reader_.wait != nullptr; }
  [[nodiscard]] const ds1928_shm_header& header() const noexcept { return *reader_.header; }
  [[nodiscard]] uint32_t axis_count() const noexcept { return reader_.header->axis_count; }
  [[nodiscard]] uint64_t generation() const noexcept { return reader_.generation; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] uint32_t daemon_state() const noexcept {
    return ds1928_shm_daemon_state(reader_.header);
  }
  [[nodiscard]] bool daemon_alive(uint32_t missed_cycles = 10) const noexcept {
    return ds1928_shm_daemon_alive(reader_.header, ds1928_shm_now_ns(), missed_cycles) != 0;
  }
  [[nodiscard]] uint64_t wait_start() const noexcept {
    return ds1928_shm_wait_start(reader_.header);
  }

  // Consistent copy of one axis record (seqlock).
  [[nodiscard]] std::error_code read(uint32_t axis, ds1928_axis_data& out) const noexcept {
    if (const int rc = ds1928_shm_read_axis(reader_.header, axis, &out); rc != 0)
      return {-rc, std::generic_category()};
    return {};
  }

  // The additional-information channels (DS1928_SHM_FEATURE_INFO): a record with its channels
  // (errc::not_supported from a daemon without them) and a channel's name (nullptr: off).
  [[nodiscard]] bool has_info() const noexcept { return ds1928_shm_has_info(reader_.header) != 0; }
  [[nodiscard]] std::error_code read(uint32_t axis, ds1928_axis_data& out,
                                     ds1928_axis_info& info) const noexcept {
    if (const int rc = ds1928_shm_read_axis_info(reader_.header, axis, &out, &info); rc != 0)
      return {-rc, std::generic_category()};
    return {};
  }
  [[nodiscard]] const char* info_name(uint32_t axis, uint32_t channel) const noexcept {
    return ds1928_shm_info_name(reader_.header, reader_.size, axis, channel);
  }

  // ds1928_shm_wait: the next publication whose cycle index is a multiple of `every`.
  [[nodiscard]] ShmWait wait(uint64_t& seen_cycle, uint32_t every, int64_t deadline_ns,
                             std::error_code& error) const noexcept {
    const int rc = ds1928_shm_wait(&reader_, &seen_cycle, every, deadline_ns);
    error.clear();
    if (rc == DS1928_SHM_TIMEOUT) return ShmWait::Timeout;
    if (rc == DS1928_SHM_STOPPED) return ShmWait::Stopped;
    if (rc < 0) {
      error = {-rc, std::generic_category()};
      return ShmWait::Timeout;
    }
    return ShmWait::Published;
  }

 private:
  ds1928_shm_reader reader_{};
  std::string name_;
};

}  // namespace ds1928
