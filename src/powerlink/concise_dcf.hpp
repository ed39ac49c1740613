// Concise DCF (CDC): the binary object list a POWERLINK/CANopen configuration tool writes
// (EPSG DS 301 / CiA 302; openCONFIGURATOR's mnobd.cdc). Little endian throughout:
//   u32 number of entries, then per entry: u16 index | u8 subindex | u32 data size | data.
// The MN's own file holds its objects, among them CFM_ConciseDcfList/<node>: a domain that is
// itself a concise DCF, the objects the MN writes to that CN when it configures it. The objects
// it names are in standard_objects.hpp.
// Pure codec: bytes in, entries out (and back); no I/O.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "powerlink/standard_objects.hpp"

namespace ds1928::powerlink {

inline constexpr std::size_t kCdcEntryHeaderSize = 7;  // index, subindex, size

struct CdcEntry {
  uint16_t index = 0;
  uint8_t subindex = 0;
  std::vector<uint8_t> data;
  // Where the entry's header starts in the file decode_cdc() read (messages name it); not part
  // of the entry's identity.
  std::size_t offset = 0;
  friend bool operator==(const CdcEntry& a, const CdcEntry& b) noexcept {
    return a.index == b.index && a.subindex == b.subindex && a.data == b.data;
  }

  // The value as an unsigned little-endian number; nullopt when empty or longer than 8 bytes.
  [[nodiscard]] std::optional<uint64_t> as_unsigned() const noexcept;
};

// Why a byte string is not a concise DCF, and where.
struct CdcError {
  std::size_t offset = 0;  // byte offset in the file where the problem is
  std::size_t entry = 0;   // 0-based entry being read (or the count for a count problem)
  std::string message;     // "entry 3 (<index>/1) announces 8 data bytes, only 5 remain", ...
};

struct CdcDecodeResult {
  std::vector<CdcEntry> entries;
  std::optional<CdcError> error;  // set: `entries` holds those read before the problem
  [[nodiscard]] bool ok() const noexcept { return !error.has_value(); }
};

// Decodes a whole file. A count of 0, a count larger than the bytes could hold, a truncated
// entry header or data, and bytes after the last entry are errors.
[[nodiscard]] CdcDecodeResult decode_cdc(std::span<const uint8_t> bytes);

// The inverse (tests, tools); entries as given.
[[nodiscard]] std::vector<uint8_t> encode_cdc(std::span<const CdcEntry> entries);

// The last entry for index/subindex in `entries` (the value the object ends up with when the
// list is written in order), or nullptr.
[[nodiscard]] const CdcEntry* find_cdc_entry(std::span<const CdcEntry> entries, uint16_t index,
                                             uint8_t subindex) noexcept;

// "0x1600/1" (for messages).
// The standard object's name of index/subindex ("PDO_RxMappParam_00h_AU64.ObjectMapping"), or
// empty when the table does not have it (a device's own object).
[[nodiscard]] std::string_view standard_name(uint16_t index, uint8_t subindex) noexcept;
[[nodiscard]] std::string object_name(uint16_t index, uint8_t subindex);

}  // namespace ds1928::powerlink

namespace ds1928::powerlink {

// PDO mapping (obj::kRxPdoMapping.. RPDO = the CN's PReq payload, obj::kTxPdoMapping.. TPDO =
// its PRes payload):
// sub 0 = number of entries; each entry u64 = length bits 63..48 | offset bits 47..32 |
// reserved 31..24 | subindex 23..16 | index 15..0, offset and length in bits.
struct PdoMapEntry {
  uint16_t index = 0;
  uint8_t subindex = 0;
  uint16_t offset_bits = 0;
  uint16_t length_bits = 0;
  [[nodiscard]] static PdoMapEntry from_u64(uint64_t v) noexcept {
    return {static_cast<uint16_t>(v), static_cast<uint8_t>(v >> 16), static_cast<uint16_t>(v >> 32),
            static_cast<uint16_t>(v >> 48)};
  }
  [[nodiscard]] uint64_t to_u64() const noexcept {
    return static_cast<uint64_t>(index) | static_cast<uint64_t>(subindex) << 16 |
           static_cast<uint64_t>(offset_bits) << 32 | static_cast<uint64_t>(length_bits) << 48;
  }
};

// What an object list written to a CN says about its process image: the payload sizes from
// NMT_CycleTiming /4 and /5 when written, else from the end of the last mapped object of the
// first RPDO / TPDO mapping (entries 1..sub 0); nullopt when the list says nothing about it.
struct ImageSizes {
  std::optional<uint16_t> preq_size;
  std::optional<uint16_t> pres_size;
};
[[nodiscard]] ImageSizes image_sizes_from_objects(std::span<const CdcEntry> objects) noexcept;

}  // namespace ds1928::powerlink
