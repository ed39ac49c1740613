// ManagingNode: the process image of each CN — packed, from the PDO mapping written to it, or
// from its own mapping read by SDO at boot (docs/powerlink.md §Process image from the PDO
// mapping).
#include <algorithm>
#include <new>

#include "core/sdo_abort.hpp"
#include "powerlink/managing_node.hpp"
#include "powerlink/managing_node_cn.hpp"
#include "powerlink/pdo_image.hpp"

namespace ds1928::powerlink {

std::string_view to_string(ImageSource s) noexcept {
  switch (s) {
    case ImageSource::kPacked:
      return "packed";
    case ImageSource::kWrittenMapping:
      return "written_mapping";
    case ImageSource::kReadMapping:
      return "read_mapping";
    case ImageSource::kRefused:
      return "refused";
  }
  return "?";
}

// The process image of a CN (docs/powerlink.md §Process image): from the PDO mapping its objects
// write (0x1A00/0x1600, its concise DCF or sdo_writes) through the object scheme, or packed.
// Throws what names the node and the entry, slot or register at fault.
NodeImageLayout ManagingNode::image_layout(const PowerlinkNodeConfig& nc,
                                           std::span<const CdcEntry> written,
                                           std::span<const ModuleSpec> specs) const {
  const std::string node = "process image of node " + std::to_string(nc.node_id);
  const auto tpdo = mapping_from_objects(written, obj::kTxPdoMapping);
  const auto rpdo = mapping_from_objects(written, obj::kRxPdoMapping);
  const bool has_mapping = tpdo && !tpdo->empty();
  // Without a written mapping (auto, mapping) the packed blocks serve until the CN's own mapping
  // is read at boot (bind_read_mapping()).
  if (nc.layout != ImageLayout::kPacked && has_mapping) {
    PdoMappingLists lists;
    lists.tpdo = *tpdo;
    if (rpdo) lists.rpdo = *rpdo;
    PdoBindIssue issue;
    auto layout =
        bind_pdo_mapping(lists, nc.object_scheme.value_or(config_.bus.object_scheme), specs, issue);
    if (!layout) throw std::system_error(issue.error, node + ", " + std::string(issue.what.view()));
    return *layout;
  }
  LayoutIssue issue;
  auto layout = make_layout(specs, &issue);
  if (!layout) {
    std::string what =
        node + ", " + (issue.in_preq ? "PReq" : "PRes") + ": slot " + std::to_string(issue.slot);
    if (issue.other_slot != 0) what += " and slot " + std::to_string(issue.other_slot);
    throw std::system_error(layout.error(), what);
  }
  return *layout;
}

void ManagingNode::init_image(Cn& cn, std::span<const CdcEntry> written,
                              std::span<const ModuleSpec> specs) {
  cn.layout = image_layout(cn.cfg, written, specs);
  cn.specs.assign(specs.begin(), specs.end());
  cn.packed_layout = cn.layout;
  if (cn.cfg.layout != ImageLayout::kPacked) {
    const auto tpdo = mapping_from_objects(written, obj::kTxPdoMapping);
    if (tpdo && !tpdo->empty()) {
      // Kept for status: what the image was bound from.
      const auto rpdo = mapping_from_objects(written, obj::kRxPdoMapping);
      cn.st->image_source = ImageSource::kWrittenMapping;
      cn.map_tpdo_count = static_cast<uint8_t>(std::min(tpdo->size(), kMaxReadMapEntries));
      std::copy_n(tpdo->begin(), cn.map_tpdo_count, cn.map_tpdo.begin());
      if (rpdo) {
        cn.map_rpdo_count = static_cast<uint8_t>(std::min(rpdo->size(), kMaxReadMapEntries));
        std::copy_n(rpdo->begin(), cn.map_rpdo_count, cn.map_rpdo.begin());
      }
    } else if (cn.cfg.prc) {
      // A chained node's outputs sit in the PResMN where the MN's written RPDO says, laid out
      // as its image is from the start: its image cannot change at boot.
      if (cn.cfg.layout == ImageLayout::kMapping)
        throw std::system_error(make_error_code(MnError::kPdoRegisterNotMapped),
                                "process image of node " + std::to_string(cn.cfg.node_id) +
                                    ": layout mapping on a PollResponse Chaining node needs "
                                    "its TPDO mapping (PDO_TxMappParam) among the objects "
                                    "written to it");
    } else if (!specs.empty()) {
      cn.read_mapping = true;
      cn.map_read = MapRead::kTpdo;
    }
  }
}

std::span<const PdoMapEntry> ManagingNode::mapped_objects(uint8_t id, bool tpdo) const noexcept {
  const Cn* cn = find(id);
  if (!cn) return {};
  return tpdo ? std::span<const PdoMapEntry>(cn->map_tpdo.data(), cn->map_tpdo_count)
              : std::span<const PdoMapEntry>(cn->map_rpdo.data(), cn->map_rpdo_count);
}

void ManagingNode::start_mapping_read(Cn& cn) noexcept {
  cn.op_active = true;
  cn.op_internal = true;
  cn.op_kind = OpKind::kMappingRead;
  const uint16_t index = cn.map_read == MapRead::kTpdo ? obj::kTxPdoMapping : obj::kRxPdoMapping;
  const std::error_code ec = cn.sdo->read(index, cn.map_sub, now_ns_);
  if (ec) {
    cn.op_active = false;
    sdo_done(cn, ec, {});
  }
}

void ManagingNode::mapping_read_done(Cn& cn, std::error_code ec,
                                     std::span<const uint8_t> data) noexcept {
  const bool tpdo = cn.map_read == MapRead::kTpdo;
  uint8_t& count = tpdo ? cn.map_tpdo_count : cn.map_rpdo_count;
  bool direction_done = false;
  if (ec) {
    // This direction maps nothing. A CN without the mapping object (abort 0x06020000 on sub 0)
    // simply has none; any other failure (an entry unreadable, no answer) is reported.
    const bool no_object = cn.map_sub == 0 && ec == make_sdo_abort_error(sdo_abort::kNoObject);
    CnStatus& st = *cn.st;
    if (!no_object) {
      ++st.object_failures;
      if (st.last_failure_count < st.last_failures.size())
        st.last_failures[st.last_failure_count++] = {tpdo ? obj::kTxPdoMapping : obj::kRxPdoMapping,
                                                     cn.map_sub, true, ec};
    }
    count = 0;
    direction_done = true;
  } else {
    uint64_t v = 0;
    for (std::size_t i = 0; i < std::min<std::size_t>(data.size(), 8); ++i)
      v |= static_cast<uint64_t>(data[i]) << (8 * i);
    if (cn.map_sub == 0) {
      cn.map_count = static_cast<uint8_t>(std::min<uint64_t>(v, kMaxReadMapEntries));
      count = 0;
    } else {
      (tpdo ? cn.map_tpdo : cn.map_rpdo)[cn.map_sub - 1] = PdoMapEntry::from_u64(v);
      count = cn.map_sub;
    }
    direction_done = cn.map_sub >= cn.map_count;
    if (!direction_done) ++cn.map_sub;
  }
  if (!direction_done) return;
  cn.map_sub = cn.map_count = 0;
  // A CN that maps no TPDO has no RPDO worth reading for its modules either.
  if (tpdo && cn.map_tpdo_count > 0) {
    cn.map_read = MapRead::kRpdo;
    return;
  }
  cn.map_read = MapRead::kDone;
  bind_read_mapping(cn);
}

void ManagingNode::bind_read_mapping(Cn& cn) noexcept {
  CnStatus& st = *cn.st;
  ++layouts_version_;
  auto refuse = [&](std::error_code error, std::string_view what) {
    st.image_source = ImageSource::kRefused;
    st.image_error = error;
    st.last_error = error;
    st.image_refusal.fill('\0');
    std::copy_n(what.begin(), std::min(what.size(), st.image_refusal.size() - 1),
                st.image_refusal.begin());
    cn.layout = NodeImageLayout{};  // no axis of the node is fed from a mapping it cannot use
  };
  if (cn.map_tpdo_count == 0) {
    if (cn.cfg.layout == ImageLayout::kMapping) {
      refuse(make_error_code(MnError::kPdoRegisterNotMapped),
             "layout mapping, but the CN maps no TPDO (PDO_TxMappParam NumberOfEntries 0)");
      return;
    }
    st.image_source = ImageSource::kPacked;
    st.image_error = {};
    cn.layout = cn.packed_layout;
    return;
  }
  PdoMappingLists lists;
  lists.tpdo = std::span<const PdoMapEntry>(cn.map_tpdo.data(), cn.map_tpdo_count);
  lists.rpdo = std::span<const PdoMapEntry>(cn.map_rpdo.data(), cn.map_rpdo_count);
  const PdoObjectScheme& scheme = cn.cfg.object_scheme.value_or(config_.bus.object_scheme);
  // A module missing a register is left out (its axis is refused, named in image_refusal) and
  // the others are bound again: one module's gap does not stop its neighbours.
  std::array<ModuleSpec, kMaxModulesPerNode> specs{};
  std::size_t count = std::min(cn.specs.size(), specs.size());
  std::copy_n(cn.specs.begin(), count, specs.begin());
  st.image_refusal.fill('\0');
  st.image_error = {};
  std::size_t said = 0;
  for (;;) {
    PdoBindIssue issue;
    if (auto layout = bind_pdo_mapping(lists, scheme, std::span(specs.data(), count), issue)) {
      cn.layout = *layout;
      st.image_source = ImageSource::kReadMapping;
      return;
    }
    const auto refused = std::find_if(specs.begin(), specs.begin() + count,
                                      [&](const ModuleSpec& m) { return m.slot == issue.slot; });
    if (issue.error != MnError::kPdoRegisterNotMapped || refused == specs.begin() + count) {
      refuse(issue.error, issue.what);
      return;
    }
    // "slot 2: PositionHW (0x2002/1) is not mapped; slot 3: ..." as far as it fits.
    st.image_error = issue.error;
    st.last_error = issue.error;
    const std::string_view what = issue.what.view();
    const std::string_view sep = said > 0 ? "; " : "";
    for (std::string_view part : {sep, what})
      for (char c : part)
        if (said + 1 < st.image_refusal.size()) st.image_refusal[said++] = c;
    std::copy(refused + 1, specs.begin() + count, refused);
    if (--count == 0) {
      st.image_source = ImageSource::kRefused;
      cn.layout = NodeImageLayout{};
      return;
    }
  }
}

}  // namespace ds1928::powerlink
