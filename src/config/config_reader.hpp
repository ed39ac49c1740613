// Shared pieces of the configuration reader: positions, diagnostics, scalar parsing and the
// Section reader every config_*.cpp file uses. Internal to src/config.
#pragma once

#include <fcntl.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "config/config_loader.hpp"

namespace ds1928::config_detail {

struct Loc {
  int line = 0;
  int column = 0;
};

inline Loc loc_of(const YAML::Mark& m) {
  if (m.is_null() || m.line < 0) return {};
  return {m.line + 1, m.column + 1};
}

inline std::string where(Loc l) {
  return "line " + std::to_string(l.line);
}

class Diagnostics {
 public:
  explicit Diagnostics(std::string file) : file_(std::move(file)) {}

  void error(Loc at, std::string key, std::string message) {
    errors_.push_back(ConfigError{file_, at.line, at.column, std::move(key), std::move(message)});
  }
  [[nodiscard]] bool empty() const noexcept { return errors_.empty(); }
  [[nodiscard]] std::vector<ConfigError> take() {
    std::stable_sort(errors_.begin(), errors_.end(), [](const auto& a, const auto& b) {
      return std::pair(a.line, a.column) < std::pair(b.line, b.column);
    });
    return std::move(errors_);
  }

 private:
  std::string file_;
  std::vector<ConfigError> errors_;
};

// ---------------------------------------------------------------------------------------------
// Scalar parsing

// Files the configuration names (itself, encoder files) are read whole: bounded.
inline constexpr std::uintmax_t kMaxFileBytes = 1024 * 1024;

// A value as quoted in a message: a bounded prefix of it (a 50 MB string is not repeated).
inline std::string excerpt(std::string_view s) {
  constexpr std::size_t kMax = 80;
  if (s.size() <= kMax) return std::string(s);
  return std::string(s.substr(0, kMax)) + "... (" + std::to_string(s.size()) + " characters)";
}

// Why `p` cannot serve as a small text file ("" when it can): missing, not a regular file, too
// large, or unreadable although stat calls it regular (/proc/self/mem).
inline std::string unusable_file(const std::filesystem::path& p) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(p, ec);
  if (!fs::exists(st)) return "no such file: " + p.string();
  if (!fs::is_regular_file(st)) {
    const char* kind = fs::is_directory(st)        ? "a directory"
                       : fs::is_character_file(st) ? "a character device"
                       : fs::is_block_file(st)     ? "a block device"
                       : fs::is_fifo(st)           ? "a FIFO"
                       : fs::is_socket(st)         ? "a socket"
                                                   : "not a file";
    return "not a regular file: " + p.string() + " is " + kind;
  }
  if (const auto size = fs::file_size(p, ec); !ec && size > kMaxFileBytes)
    return p.string() + " is " + std::to_string(size) + " bytes; at most " +
           std::to_string(kMaxFileBytes) + " are accepted";
  const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  char byte;
  const bool readable = fd >= 0 && ::read(fd, &byte, 1) >= 0;
  const int err = errno;
  if (fd >= 0) ::close(fd);
  if (!readable) return "cannot read " + p.string() + ": " + std::generic_category().message(err);
  return {};
}

inline std::string describe(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Map:
      return "a map";
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return "an empty value";
    case YAML::NodeType::Scalar:
      break;
  }
  return n.Tag() == "?" ? "'" + excerpt(n.Scalar()) + "'"
                        : "the string \"" + excerpt(n.Scalar()) + "\"";
}

inline bool is_plain(const YAML::Node& n) {
  return n.IsScalar() && n.Tag() == "?";
}

struct IntParse {
  enum class Status { Ok, Syntax, LeadingZero, Overflow } status = Status::Syntax;
  int64_t value = 0;
};

// Decimal or 0x hex, optional sign. A leading zero is refused because YAML 1.1 would read it
// as octal and a reader of the file cannot tell which was meant.
inline IntParse parse_integer(std::string_view s) {
  IntParse r;
  bool negative = false;
  if (!s.empty() && (s.front() == '+' || s.front() == '-')) {
    negative = s.front() == '-';
    s.remove_prefix(1);
  }
  int base = 10;
  if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
    base = 16;
    s.remove_prefix(2);
  } else if (s.size() > 1 && s[0] == '0') {
    r.status = std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; })
                   ? IntParse::Status::LeadingZero
                   : IntParse::Status::Syntax;
    return r;
  }
  if (s.empty()) return r;
  uint64_t magnitude = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), magnitude, base);
  if (end != s.data() + s.size()) return r;
  constexpr uint64_t kMaxPositive = static_cast<uint64_t>(std::numeric_limits<int64_t>::max());
  if (ec == std::errc::result_out_of_range || magnitude > kMaxPositive + (negative ? 1 : 0)) {
    r.status = IntParse::Status::Overflow;
    return r;
  }
  if (ec != std::errc{}) return r;
  r.status = IntParse::Status::Ok;
  r.value = negative ? static_cast<int64_t>(0 - magnitude) : static_cast<int64_t>(magnitude);
  return r;
}

inline std::optional<double> parse_real(std::string_view s) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  double v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc{} || end != s.data() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

inline std::optional<bool> parse_bool(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  if (s == "true" || s == "yes" || s == "on") return true;
  if (s == "false" || s == "no" || s == "off") return false;
  return std::nullopt;
}

inline std::string range_text(int64_t lo, int64_t hi) {
  return std::to_string(lo) + ".." + std::to_string(hi);
}

inline std::string real_text(double v) {
  std::array<char, 64> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return ec == std::errc{} ? std::string(buf.data(), end) : std::string("?");
}

inline size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) ==
                        std::tolower(static_cast<unsigned char>(b[j - 1]));
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (same ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

// The closest candidate when it is plausibly a typo of `word`.
inline std::optional<std::string> closest(std::string_view word,
                                          const std::vector<std::string>& options) {
  std::optional<std::string> best;
  size_t best_distance = std::numeric_limits<size_t>::max();
  for (const auto& o : options) {
    const size_t d = edit_distance(word, o);
    if (d < best_distance) {
      best_distance = d;
      best = o;
    }
  }
  const size_t limit = std::max<size_t>(2, std::min(word.size(), best ? best->size() : 0) / 3);
  if (best && best_distance <= limit) return best;
  // An abbreviation of a longer key ("rt_prio" for "rt_priority").
  if (word.size() >= 3) {
    for (const auto& o : options) {
      if (o.size() > word.size() && o.compare(0, word.size(), word) == 0) return o;
    }
  }
  return std::nullopt;
}

inline std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& i : items) out += (out.empty() ? "" : ", ") + i;
  return out;
}

// ---------------------------------------------------------------------------------------------
// One YAML map of settings. Every accessor registers its key as known; finish() reports the rest.

class Section {
 public:
  Section(Diagnostics& diag, const YAML::Node& node, std::string path, Loc at)
      : diag_(&diag), path_(std::move(path)), at_(at) {
    if (!node.IsDefined() || node.IsNull()) return;
    if (!node.IsMap()) {
      diag_->error(at_, path_, "expected a map of settings, got " + describe(node));
      return;
    }
    for (auto it = node.begin(); it != node.end(); ++it) {
      const Loc key_at = loc_of(it->first.Mark());
      if (!it->first.IsScalar()) {
        diag_->error(key_at, path_, "a key must be a plain name, got " + describe(it->first));
        continue;
      }
      const std::string key = it->first.Scalar();
      if (const auto found = entries_.find(key); found != entries_.end()) {
        diag_->error(key_at, child(key),
                     "duplicate key (first given at " + where(found->second.key_at) + ")");
        continue;
      }
      entries_.emplace(key, Entry{key_at, it->second});
    }
  }
  Section(const Section&) = delete;
  Section& operator=(const Section&) = delete;

  [[nodiscard]] std::string child(std::string_view key) const {
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }
  [[nodiscard]] Loc at() const noexcept { return at_; }
  [[nodiscard]] Diagnostics& diag() const noexcept { return *diag_; }

  // Registers `key` as known; the value node when the key is present.
  const YAML::Node* find(std::string_view key) {
    known_.emplace_back(key);
    const auto it = entries_.find(std::string(key));
    return it == entries_.end() ? nullptr : &it->second.value;
  }
  [[nodiscard]] bool has(std::string_view key) const {
    return entries_.count(std::string(key)) != 0;
  }

  // Where the value of `key` is (the key itself for an empty value, the map when absent).
  [[nodiscard]] Loc value_at(std::string_view key) const {
    const auto it = entries_.find(std::string(key));
    if (it == entries_.end()) return at_;
    const YAML::Node& v = it->second.value;
    if (!v.IsDefined() || v.IsNull()) return it->second.key_at;
    const Loc l = loc_of(v.Mark());
    return l.line == 0 ? it->second.key_at : l;
  }

  void error(std::string_view key, std::string message) {
    diag_->error(value_at(key), child(key), std::move(message));
  }

  // A nested map; an absent key gives an empty section (all defaults).
  [[nodiscard]] Section section(std::string_view key) {
    const YAML::Node* v = find(key);
    return Section(*diag_, v ? *v : YAML::Node(YAML::NodeType::Undefined), child(key),
                   value_at(key));
  }

  template <class T>
  bool integer(std::string_view key, T& out, int64_t lo, int64_t hi, std::string_view note = {}) {
    int64_t v = 0;
    if (!integer_value(key, v, lo, hi, note)) return false;
    out = static_cast<T>(v);
    return true;
  }

  template <class T>
  bool optional_integer(std::string_view key, std::optional<T>& out, int64_t lo, int64_t hi) {
    const YAML::Node* v = find(key);
    if (!v || v->IsNull()) return false;
    T value{};
    if (!integer(key, value, lo, hi)) return false;
    out = value;
    return true;
  }

  bool real(std::string_view key, double& out, double lo, double hi) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    const std::string expected = "a number in " + real_text(lo) + ".." + real_text(hi);
    if (!is_plain(*v)) {
      error(key, "expected " + expected + ", got " + describe(*v));
      return false;
    }
    const auto parsed = parse_real(v->Scalar());
    if (!parsed) {
      error(key, "expected " + expected + ", got " + describe(*v));
      return false;
    }
    if (*parsed < lo || *parsed > hi) {
      error(key, excerpt(v->Scalar()) + " is out of range " + real_text(lo) + ".." + real_text(hi));
      return false;
    }
    out = *parsed;
    return true;
  }

  bool boolean(std::string_view key, bool& out) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    const auto parsed = is_plain(*v) ? parse_bool(v->Scalar()) : std::nullopt;
    if (!parsed) {
      error(key, "expected true or false, got " + describe(*v));
      return false;
    }
    out = *parsed;
    return true;
  }

  // A string; an empty value gives "". `max_length` counts bytes.
  bool text(std::string_view key, std::string& out, size_t max_length = 4096) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    if (v->IsNull()) {
      out.clear();
      return true;
    }
    if (!v->IsScalar()) {
      error(key, "expected a string, got " + describe(*v));
      return false;
    }
    if (v->Scalar().size() > max_length) {
      error(key, "is " + std::to_string(v->Scalar().size()) + " characters long; at most " +
                     std::to_string(max_length) + " are allowed");
      return false;
    }
    out = v->Scalar();
    return true;
  }

  // One of a fixed set of words.
  template <class E>
  bool choice(std::string_view key, E& out,
              std::initializer_list<std::pair<std::string_view, E>> options) {
    return choice_of(key, out, options);
  }
  // The same over any range of (word, value) pairs (a table built elsewhere).
  template <class E, class Options>
  bool choice_of(std::string_view key, E& out, const Options& options) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    std::vector<std::string> names;
    for (const auto& [name, value] : options) {
      if (v->IsScalar() && v->Scalar() == name) {
        out = value;
        return true;
      }
      names.emplace_back(name);
    }
    std::string message = describe(*v) + " is not allowed; expected one of: " + join(names);
    if (v->IsScalar() && v->Scalar().size() <= 64) {
      if (const auto hint = closest(v->Scalar(), names))
        message += " (did you mean '" + *hint + "'?)";
    }
    error(key, std::move(message));
    return false;
  }

  // A file mode, always read as octal like chmod does: "0640", 0640, 640 or 0o640.
  bool mode(std::string_view key, uint32_t& out) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    std::string_view s = v->IsScalar() ? std::string_view(v->Scalar()) : std::string_view{};
    if (s.size() > 2 && s[0] == '0' && (s[1] == 'o' || s[1] == 'O')) s.remove_prefix(2);
    uint32_t value = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value, 8);
    if (s.empty() || ec != std::errc{} || end != s.data() + s.size()) {
      error(key, "expected an octal file mode such as \"0640\", got " + describe(*v));
      return false;
    }
    if (value > 0777) {
      error(key, excerpt(v->Scalar()) + " is out of range 0000..0777 (permission bits only)");
      return false;
    }
    out = value;
    return true;
  }

  // The items of a list with their paths; an absent or empty key gives none.
  struct Item {
    YAML::Node node;
    std::string path;
    Loc at;
  };
  std::vector<Item> list(std::string_view key) {
    std::vector<Item> items;
    const YAML::Node* v = find(key);
    if (!v || v->IsNull()) return items;
    if (!v->IsSequence()) {
      error(key, "expected a list, got " + describe(*v));
      return items;
    }
    size_t i = 0;
    for (const auto& n : *v) {
      Loc l = loc_of(n.Mark());
      if (l.line == 0 || n.IsNull()) l = value_at(key);
      items.push_back({n, child(key) + "[" + std::to_string(i++) + "]", l});
    }
    return items;
  }

  void finish() {
    for (const auto& [key, entry] : entries_) {
      if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
      std::string message = "unknown key '" + excerpt(key) + "'";
      if (const auto hint = key.size() <= 64 ? closest(key, known_) : std::nullopt) {
        message += " (did you mean '" + *hint + "'?)";
      } else {
        message += "; allowed keys here: " + join(known_);
      }
      diag_->error(entry.key_at, child(key), std::move(message));
    }
  }

 private:
  struct Entry {
    Loc key_at;
    YAML::Node value;
  };

  bool integer_value(std::string_view key, int64_t& out, int64_t lo, int64_t hi,
                     std::string_view note) {
    const YAML::Node* v = find(key);
    if (!v) return false;
    const std::string suffix = note.empty() ? std::string() : " " + std::string(note);
    const std::string expected = "an integer in " + range_text(lo, hi) + suffix;
    const std::string expected_syntax =
        "an integer (decimal or 0x hex) in " + range_text(lo, hi) + suffix;
    if (!is_plain(*v)) {
      std::string message = "expected " + expected + ", got " + describe(*v);
      if (v->IsScalar() && parse_integer(v->Scalar()).status == IntParse::Status::Ok) {
        message += " (write the number without quotes)";
      }
      error(key, std::move(message));
      return false;
    }
    const IntParse parsed = parse_integer(v->Scalar());
    switch (parsed.status) {
      case IntParse::Status::Ok:
        break;
      case IntParse::Status::LeadingZero:
        error(key, "'" + excerpt(v->Scalar()) +
                       "' has a leading zero; write a decimal number without it, or 0x hex");
        return false;
      case IntParse::Status::Overflow:
        error(key, excerpt(v->Scalar()) + " is out of range " + range_text(lo, hi) + suffix);
        return false;
      case IntParse::Status::Syntax:
        error(key, "expected " + expected_syntax + ", got " + describe(*v));
        return false;
    }
    if (parsed.value < lo || parsed.value > hi) {
      error(key, excerpt(v->Scalar()) + " is out of range " + range_text(lo, hi) + suffix);
      return false;
    }
    out = parsed.value;
    return true;
  }

  Diagnostics* diag_;
  std::string path_;
  Loc at_;
  std::map<std::string, Entry> entries_;
  std::vector<std::string> known_;
};

// ---------------------------------------------------------------------------------------------

inline constexpr int64_t kU8 = 0xFF;
inline constexpr int64_t kU16 = 0xFFFF;
inline constexpr int64_t kU32 = 0xFFFFFFFF;

inline bool valid_interface_name(const std::string& name) {
  // IFNAMSIZ - 1 bytes, no '/', no white space.
  return !name.empty() && name.size() <= 15 && name != "." && name != ".." &&
         std::none_of(name.begin(), name.end(), [](char c) {
           return c == '/' || c == ':' || std::isspace(static_cast<unsigned char>(c));
         });
}

struct AxisSite {
  Loc at;
  Loc name_at;
  Loc node_at;
  std::string path;
  Loc pres_offset_at;
  Loc preq_offset_at;
};

// Where the value at `keys` below `node` is written; the deepest existing key when the full path
// is not in the file. (Recursion instead of a loop: assigning a YAML::Node writes through it.)
inline Loc locate(const YAML::Node& node, std::initializer_list<std::string_view> keys,
                  size_t depth = 0) {
  const Loc here = loc_of(node.Mark());
  if (depth == keys.size() || !node.IsMap()) return here;
  const std::string_view key = *(keys.begin() + depth);
  for (auto it = node.begin(); it != node.end(); ++it) {
    if (!it->first.IsScalar() || it->first.Scalar() != key) continue;
    if (it->second.IsNull() || depth + 1 == keys.size()) {
      const Loc v = loc_of(it->second.Mark());
      return it->second.IsNull() || v.line == 0 ? loc_of(it->first.Mark()) : v;
    }
    return locate(it->second, keys, depth + 1);
  }
  return here;
}

inline std::string quote(std::string_view s) {
  std::string out = "\"";
  for (const char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20) {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xF];
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

inline std::string hex(uint64_t v) {
  std::array<char, 24> buf{};
  const auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v, 16);
  return "0x" + std::string(buf.data(), ec == std::errc{} ? end : buf.data());
}

inline const char* yes(bool b) {
  return b ? "true" : "false";
}

}  // namespace ds1928::config_detail
