// The incident directory (docs/operations.md "Flight recorder"): one pcapng file per incident,
// bounded in count and in total size, the oldest removed first. Files are written whole under a
// temporary name and renamed, so a reader never sees half a file. Normal thread.
#pragma once

#include <cstdint>
#include <deque>
#include <span>
#include <string>
#include <system_error>

namespace ds1928 {

class IncidentStore {
 public:
  IncidentStore(std::string dir, uint32_t max_files, uint64_t max_total_bytes);

  // Creates the directory (mode 0750) if needed and takes stock of the files already there
  // (earlier runs), pruning them to the bounds.
  [[nodiscard]] std::error_code open();
  // Writes `bytes` as NAME (a file name of make_name()) and removes the oldest files until the
  // bounds hold again. A file larger than max_total_bytes is refused (the caller makes it fit).
  [[nodiscard]] std::error_code write(const std::string& name, std::span<const uint8_t> bytes);

  [[nodiscard]] const std::string& dir() const noexcept { return dir_; }
  [[nodiscard]] std::size_t files() const noexcept { return files_.size(); }
  [[nodiscard]] uint64_t total_bytes() const noexcept { return total_; }
  [[nodiscard]] uint64_t removed() const noexcept { return removed_; }
  [[nodiscard]] uint64_t max_total_bytes() const noexcept { return max_total_; }
  struct File {
    std::string name;
    uint64_t bytes = 0;
  };
  // Oldest first.
  [[nodiscard]] const std::deque<File>& list() const noexcept { return files_; }

 private:
  void prune();

  std::string dir_;
  uint32_t max_files_;
  uint64_t max_total_;
  std::deque<File> files_;
  uint64_t total_ = 0;
  uint64_t removed_ = 0;
};

// "20261127T073512.123456Z-000042-node_reset-n1.pcapng": UTC time of the event, the run's
// incident number, the kind, the node (n) or axis (a) when there is one. Names sort by time.
[[nodiscard]] std::string incident_file_name(int64_t realtime_ns, uint64_t number,
                                             std::string_view kind, int node, int axis);
// The files this store owns: names of that form only.
[[nodiscard]] bool is_incident_file_name(std::string_view name) noexcept;

}  // namespace ds1928
