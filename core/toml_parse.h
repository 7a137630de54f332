#pragma once
// Parsing a TOML text with the project's error: one wrapper for the case file, the organ
// presets, the material library and the clip presets. Header-only; include it only from a
// translation unit that links toml++ (PkgConfig::TOMLPP).
//
// Debian's toml++ 3.3 has undefined behaviour on some non-ASCII text: its generated
// `is_non_ascii_horizontal_whitespace` reaches `__builtin_unreachable()` for 3 019 code points
// (U+00A1–U+0499, U+2C5E–U+3057 but U+3000, U+FB26–U+FEFE: the three blocks of its table that it
// neither rejects nor handles). It asks that question wherever whitespace may follow — after a
// value, between tokens, after a backslash in a multi-line string — so a case file with "ä" in
// the wrong place (found by fuzz/fuzz_case_file.cpp) made the parser's behaviour undefined.
// Those code points are swapped for private-use ones (U+E000 + their rank) before toml++ reads
// the text, and swapped back in every key, string and error message it returns. Private-use
// characters themselves are refused (no case or data file needs them).

#include "core/errors.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace organsmith {

namespace toml_text {

inline constexpr char32_t kPrivateFirst = 0xE000, kPrivateLast = 0xF8FF;

/// True for the code points toml++ 3.3 cannot classify (see the top of this file); the same
/// arithmetic as its generated table: 64 blocks of 0x3FA from U+00A0, a mask of the blocks that
/// hold no whitespace, and explicit cases for blocks 5 and 7.
constexpr bool unsafe(char32_t c) {
  if (c <= 0xA0 || c >= 0xFEFF) return false;
  const std::uint64_t block = (static_cast<std::uint64_t>(c) - 0xA0) / 0x3FA;
  if ((1ull << block) & 0x7FFFFFFFFFFFF75Eull) return false;
  return c != 0x3000 && block != 5 && block != 7;
}

/// The unsafe code points in order: the k-th is stood in for by U+E000 + k.
inline const std::vector<char32_t>& unsafe_list() {
  static const std::vector<char32_t> list = [] {
    std::vector<char32_t> l;
    for (char32_t c = 0xA1; c < 0xFEFF; ++c)
      if (unsafe(c)) l.push_back(c);
    return l;
  }();
  return list;
}

inline void append_utf8(std::string& out, char32_t c) {
  if (c < 0x80) {
    out += static_cast<char>(c);
  } else if (c < 0x800) {
    out += static_cast<char>(0xC0 | (c >> 6));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else {  // only BMP code points are mapped
    out += static_cast<char>(0xE0 | (c >> 12));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  }
}

/// Decodes a well-formed 2- or 3-byte UTF-8 sequence at t[i] (its length in `len`), else 0.
inline char32_t decode_bmp(std::string_view t, std::size_t i, std::size_t& len) {
  const auto b = [&](std::size_t k) { return static_cast<unsigned char>(t[i + k]); };
  const auto cont = [&](std::size_t k) { return i + k < t.size() && (b(k) & 0xC0) == 0x80; };
  if ((b(0) & 0xE0) == 0xC0 && cont(1)) {
    const char32_t c = (char32_t(b(0) & 0x1F) << 6) | (b(1) & 0x3F);
    len = 2;
    return c >= 0x80 ? c : 0;
  }
  if ((b(0) & 0xF0) == 0xE0 && cont(1) && cont(2)) {
    const char32_t c = (char32_t(b(0) & 0x0F) << 12) | (char32_t(b(1) & 0x3F) << 6) | (b(2) & 0x3F);
    len = 3;
    return c >= 0x800 && (c < 0xD800 || c > 0xDFFF) ? c : 0;
  }
  return 0;
}

/// Maps code points through `f` (a well-formed sequence is replaced when f returns another code
/// point; anything else is copied byte for byte).
template <class F>
std::string map_code_points(std::string_view t, F f) {
  std::string out;
  out.reserve(t.size());
  for (std::size_t i = 0; i < t.size();) {
    std::size_t len = 1;
    const char32_t c = static_cast<unsigned char>(t[i]) >= 0x80 ? decode_bmp(t, i, len) : 0;
    const char32_t m = c ? f(c) : 0;
    if (c && m != c) append_utf8(out, m);
    else out.append(t.substr(i, len));
    i += len;
  }
  return out;
}

/// The text toml++ may read: unsafe code points swapped for their private-use stand-ins.
inline std::string shield(std::string_view t) {
  const auto& list = unsafe_list();
  return map_code_points(t, [&](char32_t c) -> char32_t {
    if (!unsafe(c)) return c;
    return static_cast<char32_t>(kPrivateFirst + (std::lower_bound(list.begin(), list.end(), c) - list.begin()));
  });
}

/// The inverse of shield() on a key, string or message toml++ returns.
inline std::string unshield(std::string_view t) {
  const auto& list = unsafe_list();
  return map_code_points(t, [&](char32_t c) {
    return c >= kPrivateFirst && c < kPrivateFirst + list.size() ? list[c - kPrivateFirst] : char32_t(c);
  });
}

/// Line and column (1-based) of the first private-use code point in `t`, written or as a
/// `\\uXXXX` / `\\UXXXXXXXX` escape, or {0, 0}.
inline std::pair<int, int> first_private_use(std::string_view t) {
  const auto escaped = [&](std::size_t i) {
    if (t[i] != '\\' || i + 1 >= t.size() || (t[i + 1] != 'u' && t[i + 1] != 'U')) return false;
    const std::size_t digits = t[i + 1] == 'u' ? 4 : 8;
    if (i + 2 + digits > t.size()) return false;
    unsigned long v = 0;
    for (std::size_t k = 0; k < digits; ++k) {
      const char h = t[i + 2 + k];
      const int d = h >= '0' && h <= '9' ? h - '0' : h >= 'a' && h <= 'f' ? h - 'a' + 10 : h >= 'A' && h <= 'F' ? h - 'A' + 10 : -1;
      if (d < 0) return false;
      v = v * 16 + static_cast<unsigned long>(d);
    }
    return v >= kPrivateFirst && v <= kPrivateLast;
  };
  int line = 1, col = 0;
  for (std::size_t i = 0; i < t.size();) {
    std::size_t len = 1;
    const unsigned char b = static_cast<unsigned char>(t[i]);
    const char32_t c = b >= 0x80 ? decode_bmp(t, i, len) : 0;
    if (b == '\n') line += 1, col = 0;
    else if ((b & 0xC0) != 0x80) ++col;
    if ((c >= kPrivateFirst && c <= kPrivateLast) || escaped(i)) return {line, col};
    i += len;
  }
  return {0, 0};
}

/// unshield() on every key and string of `node`, in place.
inline void unshield_all(toml::node& node) {
  if (auto* s = node.as_string()) {
    s->get() = unshield(s->get());
  } else if (auto* a = node.as_array()) {
    for (auto& e : *a) unshield_all(e);
  } else if (auto* t = node.as_table()) {
    bool rekey = false;
    for (auto&& [k, v] : *t) {
      unshield_all(v);
      rekey = rekey || unshield(k.str()) != k.str();
    }
    if (!rekey) return;
    toml::table fresh;
    for (auto&& [k, v] : *t)
      v.visit([&, &k = k](auto&& x) { fresh.insert_or_assign(toml::key(unshield(k.str()), k.source()), std::move(x)); });
    *t = std::move(fresh);
  }
}

}  // namespace toml_text

/// Parses `text`; on a syntax error throws CaseFileError (exit 20)
/// "<what> is not valid TOML at line N: <description>" naming `source` (may be empty), with `hint`.
inline toml::table parse_toml(std::string_view text, const std::filesystem::path& source, const std::string& what,
                              std::string hint) {
  // A UTF-8 byte-order mark (some editors write one) is not part of the first key.
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
  if (const auto [line, col] = toml_text::first_private_use(text); line > 0)
    throw CaseFileError(what + " is not valid at line " + std::to_string(line) + ", column " + std::to_string(col) +
                            ": a private-use Unicode character (U+E000–U+F8FF)",
                        source, std::move(hint));
  try {
    toml::table root = toml::parse(toml_text::shield(text), source.string());
    toml_text::unshield_all(root);
    return root;
  } catch (const toml::parse_error& e) {
    throw CaseFileError(what + " is not valid TOML at line " + std::to_string(e.source().begin.line) + ": " +
                            toml_text::unshield(e.description()),
                        source, std::move(hint));
  }
}

}  // namespace organsmith
