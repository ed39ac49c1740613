// pcapng writer (https://www.ietf.org/archive/id/draft-ietf-opsawg-pcapng-02.html): the four
// block kinds a capture of the daemon's bus traffic needs, as bytes. Pure codec: no I/O, no
// clock; the caller appends the blocks to a file or a stream in order (SHB, IDBs, EPBs, ISBs).
//
// Blocks are written in the host's byte order (little-endian on every supported target) with the
// byte-order magic saying so, as every pcapng reader expects. Time stamps are nanoseconds since
// the Unix epoch: each IDB carries if_tsresol = 9.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ds1928::capture {

// LINKTYPE_* values of the tcpdump registry.
inline constexpr uint16_t kLinkTypeEthernet = 1;
inline constexpr uint16_t kLinkTypeCanSocketCan = 227;

// Block types.
inline constexpr uint32_t kSectionHeaderBlock = 0x0A0D0D0A;
inline constexpr uint32_t kInterfaceDescriptionBlock = 0x00000001;
inline constexpr uint32_t kInterfaceStatisticsBlock = 0x00000005;
inline constexpr uint32_t kEnhancedPacketBlock = 0x00000006;
inline constexpr uint32_t kByteOrderMagic = 0x1A2B3C4D;

// epb_flags bits 0-1: the packet's direction.
enum class Direction : uint8_t { Unknown = 0, Inbound = 1, Outbound = 2 };

struct InterfaceDescription {
  uint16_t link_type = kLinkTypeEthernet;
  uint32_t snap_length = 0;  // 0: no limit
  std::string name;          // if_name (omitted when empty)
  std::string description;   // if_description (omitted when empty)
};

struct InterfaceStatistics {
  uint32_t interface_id = 0;
  uint64_t time_ns = 0;        // when the statistics were taken
  uint64_t start_time_ns = 0;  // isb_starttime
  uint64_t end_time_ns = 0;    // isb_endtime
  uint64_t received = 0;       // isb_ifrecv: frames the interface passed during the capture
  uint64_t dropped = 0;        // isb_ifdrop: of those, frames lost to the capture
};

// Each function appends one complete block to `out`.
void append_section_header(std::vector<uint8_t>& out, std::string_view application);
void append_interface_description(std::vector<uint8_t>& out, const InterfaceDescription& idb);
// `data` is the captured frame (length = captured length = original length).
void append_enhanced_packet(std::vector<uint8_t>& out, uint32_t interface_id, uint64_t time_ns,
                            std::span<const uint8_t> data, Direction direction);
void append_interface_statistics(std::vector<uint8_t>& out, const InterfaceStatistics& isb);

}  // namespace ds1928::capture
