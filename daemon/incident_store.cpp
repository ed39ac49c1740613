#include "incident_store.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <ctime>
#include <filesystem>
#include <vector>

namespace ds1928 {
namespace fs = std::filesystem;

std::string incident_file_name(int64_t realtime_ns, uint64_t number, std::string_view kind,
                               int node, int axis) {
  const time_t secs = static_cast<time_t>(realtime_ns / 1000000000);
  std::tm tm{};
  ::gmtime_r(&secs, &tm);
  std::string where;
  if (node >= 0) where += fmt::format("-n{}", node);
  if (axis >= 0) where += fmt::format("-a{}", axis);
  return fmt::format("{:04}{:02}{:02}T{:02}{:02}{:02}.{:06}Z-{:06}-{}{}.pcapng", tm.tm_year + 1900,
                     tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                     (realtime_ns % 1000000000) / 1000, number % 1000000, kind, where);
}

bool is_incident_file_name(std::string_view name) noexcept {
  // YYYYMMDDTHHMMSS.uuuuuuZ-NNNNNN-...pcapng
  if (name.size() < 31 || !name.ends_with(".pcapng")) return false;
  for (std::size_t i = 0; i < 8; ++i)
    if (name[i] < '0' || name[i] > '9') return false;
  return name[8] == 'T' && name[15] == '.' && name[22] == 'Z' && name[23] == '-' && name[30] == '-';
}

IncidentStore::IncidentStore(std::string dir, uint32_t max_files, uint64_t max_total_bytes)
    : dir_(std::move(dir)), max_files_(max_files), max_total_(max_total_bytes) {}

std::error_code IncidentStore::open() {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) return ec;
  ::chmod(dir_.c_str(), 0750);
  std::vector<File> found;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_regular_file() || !is_incident_file_name(name)) continue;
    std::error_code size_ec;
    const auto size = entry.file_size(size_ec);
    if (!size_ec) found.push_back({name, size});
  }
  if (ec) return ec;
  std::sort(found.begin(), found.end(),
            [](const File& a, const File& b) { return a.name < b.name; });
  files_.assign(found.begin(), found.end());
  total_ = 0;
  for (const File& f : files_) total_ += f.bytes;
  prune();
  return {};
}

std::error_code IncidentStore::write(const std::string& name, std::span<const uint8_t> bytes) {
  if (bytes.size() > max_total_) return std::make_error_code(std::errc::file_too_large);
  if (!is_incident_file_name(name)) return std::make_error_code(std::errc::invalid_argument);
  // Room first: the bounds hold while the file is written, not only after.
  while (!files_.empty() &&
         (files_.size() + 1 > max_files_ || total_ + bytes.size() > max_total_)) {
    ::unlink((dir_ + "/" + files_.front().name).c_str());
    total_ -= files_.front().bytes;
    files_.pop_front();
    ++removed_;
  }
  const std::string path = dir_ + "/" + name;
  const std::string tmp = dir_ + "/." + name + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
  if (fd < 0) return {errno, std::generic_category()};
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::error_code ec{errno, std::generic_category()};
      ::close(fd);
      ::unlink(tmp.c_str());
      return ec;
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0 || ::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::error_code ec{errno, std::generic_category()};
    ::unlink(tmp.c_str());
    return ec;
  }
  files_.push_back({name, bytes.size()});
  total_ += bytes.size();
  prune();
  return {};
}

void IncidentStore::prune() {
  while (!files_.empty() && (files_.size() > max_files_ || total_ > max_total_)) {
    ::unlink((dir_ + "/" + files_.front().name).c_str());
    total_ -= files_.front().bytes;
    files_.pop_front();
    ++removed_;
  }
}

}  // namespace ds1928
