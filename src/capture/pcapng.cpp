#include "capture/pcapng.hpp"

#include <cstring>

namespace ds1928::capture {
namespace {

// Option codes.
constexpr uint16_t kOptEndOfOpt = 0;
constexpr uint16_t kShbUserAppl = 4;
constexpr uint16_t kIfName = 2;
constexpr uint16_t kIfDescription = 3;
constexpr uint16_t kIfTsResol = 9;
constexpr uint16_t kEpbFlags = 2;
constexpr uint16_t kIsbStartTime = 2;
constexpr uint16_t kIsbEndTime = 3;
constexpr uint16_t kIsbIfRecv = 4;
constexpr uint16_t kIsbIfDrop = 5;

template <typename T>
void put(std::vector<uint8_t>& out, T value) {
  uint8_t bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.insert(out.end(), bytes, bytes + sizeof(T));
}

void pad4(std::vector<uint8_t>& out, std::size_t length) {
  out.insert(out.end(), (4 - length % 4) % 4, 0);
}

void option(std::vector<uint8_t>& out, uint16_t code, std::span<const uint8_t> value) {
  put<uint16_t>(out, code);
  put<uint16_t>(out, static_cast<uint16_t>(value.size()));
  out.insert(out.end(), value.begin(), value.end());
  pad4(out, value.size());
}

void option(std::vector<uint8_t>& out, uint16_t code, std::string_view text) {
  option(out, code, {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
}

// pcapng time stamps: the upper and the lower 32 bits, each in the host's order.
void option_time(std::vector<uint8_t>& out, uint16_t code, uint64_t t) {
  uint8_t v[8];
  const auto hi = static_cast<uint32_t>(t >> 32), lo = static_cast<uint32_t>(t);
  std::memcpy(v, &hi, 4);
  std::memcpy(v + 4, &lo, 4);
  option(out, code, v);
}

void option_u64(std::vector<uint8_t>& out, uint16_t code, uint64_t value) {
  uint8_t v[8];
  std::memcpy(v, &value, 8);
  option(out, code, v);
}

// Opens a block: type and a placeholder for its total length. Returns where the block starts.
std::size_t open_block(std::vector<uint8_t>& out, uint32_t type) {
  const std::size_t at = out.size();
  put<uint32_t>(out, type);
  put<uint32_t>(out, 0);
  return at;
}

// Ends the options (when any were written) and closes the block: the total length at both ends.
void close_block(std::vector<uint8_t>& out, std::size_t at, bool had_options) {
  if (had_options) {
    put<uint16_t>(out, kOptEndOfOpt);
    put<uint16_t>(out, 0);
  }
  const auto total = static_cast<uint32_t>(out.size() - at + 4);
  std::memcpy(out.data() + at + 4, &total, 4);
  put<uint32_t>(out, total);
}

}  // namespace

void append_section_header(std::vector<uint8_t>& out, std::string_view application) {
  const std::size_t at = open_block(out, kSectionHeaderBlock);
  put<uint32_t>(out, kByteOrderMagic);
  put<uint16_t>(out, 1);  // major version
  put<uint16_t>(out, 0);  // minor version
  put<int64_t>(out, -1);  // section length: not known in advance (streamed)
  if (!application.empty()) option(out, kShbUserAppl, application);
  close_block(out, at, !application.empty());
}

void append_interface_description(std::vector<uint8_t>& out, const InterfaceDescription& idb) {
  const std::size_t at = open_block(out, kInterfaceDescriptionBlock);
  put<uint16_t>(out, idb.link_type);
  put<uint16_t>(out, 0);  // reserved
  put<uint32_t>(out, idb.snap_length);
  if (!idb.name.empty()) option(out, kIfName, idb.name);
  if (!idb.description.empty()) option(out, kIfDescription, idb.description);
  const uint8_t nanoseconds[1] = {9};  // 10^-9 s
  option(out, kIfTsResol, nanoseconds);
  close_block(out, at, true);
}

void append_enhanced_packet(std::vector<uint8_t>& out, uint32_t interface_id, uint64_t time_ns,
                            std::span<const uint8_t> data, Direction direction) {
  const std::size_t at = open_block(out, kEnhancedPacketBlock);
  put<uint32_t>(out, interface_id);
  put<uint32_t>(out, static_cast<uint32_t>(time_ns >> 32));
  put<uint32_t>(out, static_cast<uint32_t>(time_ns));
  put<uint32_t>(out, static_cast<uint32_t>(data.size()));  // captured
  put<uint32_t>(out, static_cast<uint32_t>(data.size()));  // original
  out.insert(out.end(), data.begin(), data.end());
  pad4(out, data.size());
  const bool flags = direction != Direction::Unknown;
  if (flags) {
    uint8_t v[4];
    const uint32_t word = static_cast<uint32_t>(direction);
    std::memcpy(v, &word, 4);
    option(out, kEpbFlags, v);
  }
  close_block(out, at, flags);
}

void append_interface_statistics(std::vector<uint8_t>& out, const InterfaceStatistics& isb) {
  const std::size_t at = open_block(out, kInterfaceStatisticsBlock);
  put<uint32_t>(out, isb.interface_id);
  put<uint32_t>(out, static_cast<uint32_t>(isb.time_ns >> 32));
  put<uint32_t>(out, static_cast<uint32_t>(isb.time_ns));
  option_time(out, kIsbStartTime, isb.start_time_ns);
  option_time(out, kIsbEndTime, isb.end_time_ns);
  option_u64(out, kIsbIfRecv, isb.received);
  option_u64(out, kIsbIfDrop, isb.dropped);
  close_block(out, at, true);
}

}  // namespace ds1928::capture
