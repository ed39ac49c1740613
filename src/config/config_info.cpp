#include "config/config_info.hpp"

#include <algorithm>

namespace ds1928::config_detail {
namespace {

bool valid_channel_name(const std::string& n) {
  return !n.empty() && n.size() <= 31 && std::all_of(n.begin(), n.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  });
}

std::string known_names() {
  std::string out;
  for (const NamedInfo& n : named_infos()) out += (out.empty() ? "" : ", ") + std::string(n.name);
  return out;
}

}  // namespace

void parse_info(Section& axis, std::string_view key, AxisConfig& a) {
  const auto items = axis.list(key);
  Diagnostics& diag = axis.diag();
  if (items.size() > kInfoChannels) {
    axis.error(key, std::to_string(items.size()) + " entries; the module has " +
                        std::to_string(kInfoChannels) + " channels (EnDatInfoCmd01..04)");
    return;
  }
  for (const auto& item : items) {
    InfoChannelConfig ch;
    if (item.node.IsScalar()) {
      const NamedInfo* n = find_named_info(item.node.Scalar());
      if (n == nullptr) {
        diag.error(item.at, item.path,
                   "'" + excerpt(item.node.Scalar()) +
                       "' is not a known additional information; expected one of: " +
                       known_names() + ", or a map with name and command/mrs");
        continue;
      }
      ch.name = std::string(n->name);
      ch.request = named_info_request(*n);
      ch.is_signed = n->is_signed;
    } else if (item.node.IsMap()) {
      Section s(diag, item.node, item.path, item.at);
      if (!s.text("name", ch.name, 31)) {
        s.error("name", "missing: a map entry needs a name (the HAL pin's and metric's label)");
      } else if (!valid_channel_name(ch.name)) {
        s.error("name", "'" + ch.name + "' is not a valid name: 1..31 letters, digits, _ -");
      }
      std::string named;
      if (s.text("info", named)) {
        const NamedInfo* n = find_named_info(named);
        if (n == nullptr) {
          s.error("info",
                  "'" + excerpt(named) +
                      "' is not a known additional information; expected one of: " + known_names());
        } else {
          ch.request = named_info_request(*n);
          ch.is_signed = n->is_signed;
        }
        for (const char* raw : {"command", "mrs", "parameter", "block"}) {
          if (!s.has(raw)) continue;
          uint8_t ignored = 0;
          (void)s.integer(raw, ignored, 0, kU8);  // a known key here, only not with info
          s.error(raw, "not with info: a named information sets the request");
        }
      } else {
        if (!s.integer("command", ch.request.command, 0, kU8))
          if (!s.has("command")) s.error("command", "missing: give info or command and mrs");
        if (!s.integer("mrs", ch.request.mrs, 0, kU8))
          if (!s.has("mrs")) s.error("mrs", "missing: the MRS code of the area to read");
        s.integer("parameter", ch.request.parameter, 0, kU8);
        uint8_t block = 0;
        if (s.integer("block", block, 0, kU8)) ch.request.block = block;
        if (s.has("command") && s.has("mrs")) {
          if (const auto why = info_request_problem(ch.request); !why.empty())
            s.error("command", std::string(why));
        }
      }
      s.boolean("signed", ch.is_signed);
      s.finish();
    } else {
      diag.error(
          item.at, item.path,
          "expected a name of an additional information or a map, got " + describe(item.node));
      continue;
    }
    for (const InfoChannelConfig& other : a.info) {
      if (other.name == ch.name) {
        diag.error(item.at, item.path, "channel name '" + ch.name + "' is used twice");
        break;
      }
    }
    a.info.push_back(std::move(ch));
  }
  for (std::size_t i = 0; i < kInfoChannels; ++i)
    a.module.info_cmd[i] = i < a.info.size() ? encode_info_command(a.info[i].request) : 0;
}

}  // namespace ds1928::config_detail
