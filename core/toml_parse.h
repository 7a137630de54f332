#pragma once
// Parsing a TOML text with the project's error: one wrapper for the case file, the organ
// presets, the material library and the clip presets. Header-only; include it only from a
// translation unit that links toml++ (PkgConfig::TOMLPP).

#include "core/errors.h"

#include <toml++/toml.h>

#include <filesystem>
#include <string>
#include <string_view>
#include <utility>

namespace organsmith {

/// Line and column (1-based) of the first non-ASCII byte outside a string or a comment, or
/// {0, 0}. TOML 1.0 allows non-ASCII text only inside strings (quoted keys included) and
/// comments. Debian's toml++ 3.3 (a shared library) reaches an unreachable point when it asks
/// whether such a character elsewhere is whitespace (U+00A1–U+0499 and U+FCA6–U+FEFE fall into
/// an unhandled branch of its generated table; found by fuzz/fuzz_case_file.cpp), so they are
/// refused first, as is one right after a backslash in a multi-line basic string or after the
/// whitespace that a line-ending backslash skips (toml++ tests those too). A quote opens a string only where TOML allows one — at the start of a line or
/// after `=`, `[`, `,`, `{` or `.` — as toml++ reads it: `x = 2c"ä"` is a bare value with ä in it.
inline std::pair<int, int> toml_non_ascii_outside_strings(std::string_view t) {
  int line = 1, col = 0;
  std::size_t i = 0;
  char prev = '\n';  // the last character outside strings and comments that was not a space or tab
  auto starts = [&](std::string_view s) { return t.substr(i, s.size()) == s; };
  auto advance = [&](std::size_t n) {
    for (std::size_t k = 0; k < n && i < t.size(); ++k, ++i) {
      if (t[i] == '\n') line += 1, col = 0;
      else if ((static_cast<unsigned char>(t[i]) & 0xC0) != 0x80) ++col;
    }
  };
  while (i < t.size()) {
    const unsigned char c = static_cast<unsigned char>(t[i]);
    if (c >= 0x80) return {line, col + 1};
    const bool string_may_start = prev == '\n' || prev == '=' || prev == '[' || prev == ',' || prev == '{' || prev == '.';
    if (c == '#') {
      while (i < t.size() && t[i] != '\n') advance(1);
    } else if (string_may_start && (starts("\"\"\"") || starts("'''"))) {
      const std::string_view close = t.substr(i, 3);
      const bool basic = close[0] == '"';
      advance(3);
      while (i < t.size() && !starts(close)) {
        if (basic && t[i] == '\\' && i + 1 < t.size()) {
          // After a backslash toml++ asks whether the next character is whitespace (a line-ending
          // backslash), and then skips whitespace up to the next character: both are tested.
          std::size_t j = i + 1;
          while (j < t.size() && (t[j] == ' ' || t[j] == '\t' || t[j] == '\r' || t[j] == '\n')) ++j;
          for (const std::size_t q : {i + 1, j})
            if (q < t.size() && static_cast<unsigned char>(t[q]) >= 0x80) {
              advance(q - i);
              return {line, col + 1};
            }
        }
        advance(basic && t[i] == '\\' ? 2 : 1);
      }
      advance(3);
      prev = '"';
    } else if (string_may_start && (c == '"' || c == '\'')) {
      advance(1);
      while (i < t.size() && t[i] != static_cast<char>(c) && t[i] != '\n') advance(c == '"' && t[i] == '\\' ? 2 : 1);
      if (i < t.size() && t[i] == static_cast<char>(c)) advance(1);
      prev = '"';
    } else {
      if (c != ' ' && c != '\t' && c != '\r') prev = static_cast<char>(c);
      advance(1);
    }
  }
  return {0, 0};
}

/// Parses `text`; on a syntax error throws CaseFileError (exit 20)
/// "<what> is not valid TOML at line N: <description>" naming `source` (may be empty), with `hint`.
inline toml::table parse_toml(std::string_view text, const std::filesystem::path& source, const std::string& what,
                              std::string hint) {
  if (const auto [line, col] = toml_non_ascii_outside_strings(text); line > 0)
    throw CaseFileError(what + " is not valid TOML at line " + std::to_string(line) + ", column " + std::to_string(col) +
                            ": a non-ASCII character outside a string or a comment",
                        source, std::move(hint));
  try {
    return toml::parse(text, source.string());
  } catch (const toml::parse_error& e) {
    throw CaseFileError(what + " is not valid TOML at line " + std::to_string(e.source().begin.line) + ": " +
                            std::string(e.description()),
                        source, std::move(hint));
  }
}

}  // namespace organsmith
