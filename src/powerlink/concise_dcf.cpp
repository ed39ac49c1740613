#include "powerlink/concise_dcf.hpp"

#include <algorithm>
#include <array>
#include <cstdio>

namespace ds1928::powerlink {
namespace {

uint32_t le32(const uint8_t* p) noexcept {
  return static_cast<uint32_t>(p[0]) | static_cast<uint32_t>(p[1]) << 8 |
         static_cast<uint32_t>(p[2]) << 16 | static_cast<uint32_t>(p[3]) << 24;
}

void put_le(std::vector<uint8_t>& out, uint64_t v, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
}

}  // namespace

std::optional<uint64_t> CdcEntry::as_unsigned() const noexcept {
  if (data.empty() || data.size() > 8) return std::nullopt;
  uint64_t v = 0;
  for (std::size_t i = 0; i < data.size(); ++i) v |= static_cast<uint64_t>(data[i]) << (8 * i);
  return v;
}

std::string object_name(uint16_t index, uint8_t subindex) {
  std::array<char, 16> buf{};
  std::snprintf(buf.data(), buf.size(), "0x%04X/%u", index, subindex);
  return buf.data();
}

std::string_view standard_name(uint16_t index, uint8_t subindex) noexcept {
  const StandardObject* o = find_standard_object(index, subindex);
  return o ? o->name : std::string_view{};
}

namespace {
// "0x1C14/0 DLL_CNLossOfSocTolerance_U32", or "0x2000/1" for an object outside the table.
std::string entry_name(uint16_t index, uint8_t subindex) {
  std::string s = object_name(index, subindex);
  if (const std::string_view n = standard_name(index, subindex); !n.empty()) {
    s += ' ';
    s += n;
  }
  return s;
}
}  // namespace

CdcDecodeResult decode_cdc(std::span<const uint8_t> bytes) {
  CdcDecodeResult r;
  auto fail = [&r](std::size_t offset, std::size_t entry, std::string message) {
    r.error = CdcError{offset, entry, std::move(message)};
    return std::move(r);
  };
  if (bytes.size() < 4) {
    return fail(0, 0,
                "is " + std::to_string(bytes.size()) +
                    " bytes long; a concise DCF starts with a 4-byte entry count");
  }
  const uint32_t count = le32(bytes.data());
  if (count == 0) return fail(0, 0, "holds no entries (entry count 0)");
  // Each entry takes at least its 7-byte header. A count far beyond that (no object dictionary
  // has 65536 entries) is garbage, not a file; a small excess is a truncated file, reported at
  // the entry where it ends.
  const std::size_t room = (bytes.size() - 4) / kCdcEntryHeaderSize;
  if (count > room && count > 0xFFFF) {
    return fail(0, 0,
                "announces " + std::to_string(count) + " entries but its " +
                    std::to_string(bytes.size()) + " bytes can hold at most " +
                    std::to_string(room) + " (not a concise DCF, or truncated)");
  }
  r.entries.reserve(std::min<std::size_t>(count, room));
  std::size_t pos = 4;
  for (uint32_t i = 0; i < count; ++i) {
    if (bytes.size() - pos < kCdcEntryHeaderSize) {
      return fail(pos, i,
                  "entry " + std::to_string(i) + " of " + std::to_string(count) +
                      " is truncated: its 7-byte header needs bytes " + std::to_string(pos) + ".." +
                      std::to_string(pos + kCdcEntryHeaderSize - 1) + ", the file ends at " +
                      std::to_string(bytes.size()));
    }
    CdcEntry e;
    e.offset = pos;
    e.index = static_cast<uint16_t>(bytes[pos] | bytes[pos + 1] << 8);
    e.subindex = bytes[pos + 2];
    const uint32_t size = le32(bytes.data() + pos + 3);
    pos += kCdcEntryHeaderSize;
    if (size > bytes.size() - pos) {
      return fail(pos, i,
                  "entry " + std::to_string(i) + " (" + entry_name(e.index, e.subindex) +
                      ") announces " + std::to_string(size) + " data bytes, only " +
                      std::to_string(bytes.size() - pos) + " remain");
    }
    e.data.assign(bytes.begin() + static_cast<std::ptrdiff_t>(pos),
                  bytes.begin() + static_cast<std::ptrdiff_t>(pos + size));
    pos += size;
    r.entries.push_back(std::move(e));
  }
  if (pos != bytes.size()) {
    return fail(pos, count,
                std::to_string(bytes.size() - pos) + " bytes follow the last of the " +
                    std::to_string(count) + " announced entries");
  }
  return r;
}

std::vector<uint8_t> encode_cdc(std::span<const CdcEntry> entries) {
  std::vector<uint8_t> out;
  put_le(out, entries.size(), 4);
  for (const CdcEntry& e : entries) {
    put_le(out, e.index, 2);
    put_le(out, e.subindex, 1);
    put_le(out, e.data.size(), 4);
    out.insert(out.end(), e.data.begin(), e.data.end());
  }
  return out;
}

const CdcEntry* find_cdc_entry(std::span<const CdcEntry> entries, uint16_t index,
                               uint8_t subindex) noexcept {
  const CdcEntry* last = nullptr;
  for (const CdcEntry& e : entries)
    if (e.index == index && e.subindex == subindex) last = &e;
  return last;
}

}  // namespace ds1928::powerlink

namespace ds1928::powerlink {
namespace {

std::optional<uint16_t> mapped_size(std::span<const CdcEntry> objects, uint16_t mapping) {
  const CdcEntry* count_entry = find_cdc_entry(objects, mapping, 0);
  const auto count = count_entry ? count_entry->as_unsigned() : std::nullopt;
  if (!count) return std::nullopt;
  uint32_t end_bits = 0;
  for (uint64_t s = 1; s <= *count && s <= 254; ++s) {
    const CdcEntry* e = find_cdc_entry(objects, mapping, static_cast<uint8_t>(s));
    const auto v = e ? e->as_unsigned() : std::nullopt;
    if (!v) continue;
    const PdoMapEntry m = PdoMapEntry::from_u64(*v);
    end_bits = std::max<uint32_t>(end_bits, uint32_t{m.offset_bits} + m.length_bits);
  }
  return static_cast<uint16_t>((end_bits + 7) / 8);
}

}  // namespace

ImageSizes image_sizes_from_objects(std::span<const CdcEntry> objects) noexcept {
  ImageSizes s;
  auto limit = [&](uint8_t sub) -> std::optional<uint16_t> {
    const CdcEntry* e = find_cdc_entry(objects, obj::kCycleTiming, sub);
    const auto v = e ? e->as_unsigned() : std::nullopt;
    if (!v) return std::nullopt;
    return static_cast<uint16_t>(*v);
  };
  s.preq_size = limit(obj::kCycleTimingPReqActPayload);
  s.pres_size = limit(obj::kCycleTimingPResActPayload);
  if (!s.preq_size) s.preq_size = mapped_size(objects, obj::kRxPdoMapping);
  if (!s.pres_size) s.pres_size = mapped_size(objects, obj::kTxPdoMapping);
  return s;
}

}  // namespace ds1928::powerlink
