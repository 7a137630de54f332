#pragma once
// Comma-separated tables (RFC 4180: quoted fields may hold commas, quotes and line breaks), read
// with Debian's libcsv; its types stay in core/csv.cpp.

#include "core/errors.h"

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace organsmith {

struct CsvRow {
  int line = 0;                     ///< 1-based line of the file where the row ends
  std::vector<std::string> fields;  ///< as written, without surrounding quotes
};

struct CsvTable {
  CsvRow header;                    ///< the first row
  std::vector<CsvRow> rows;         ///< every further row

  /// Index of the header column `name`, or -1.
  int column(const std::string& name) const;
};

/// Every row of CSV text, header included, as written (rows may differ in length). A leading UTF-8
/// byte-order mark is dropped; blank lines and lines starting with '#' are skipped; spaces around
/// unquoted fields are dropped. Throws an
/// Error with `code`, naming `source` and the line, for an unterminated quote.
std::vector<CsvRow> parse_csv_rows(const std::string& text, const std::filesystem::path& source, ExitCode code);

/// Parses CSV text. Blank lines and lines starting with '#' are skipped; spaces around unquoted
/// fields are dropped. Throws an Error with `code`, naming `source` and the line, for an
/// unterminated quote, an empty table, or a row whose field count differs from the header's.
CsvTable parse_csv(const std::string& text, const std::filesystem::path& source, ExitCode code);

/// The number written in `field` (plain decimal or exponent notation, an optional leading '+'),
/// or nullopt when it is empty or not entirely a number. "nan" and "inf" parse: check finiteness.
std::optional<double> csv_number(std::string_view field);

/// Lower-cases every field of `row`: a header whose column names are case-insensitive.
void lowercase_fields(CsvRow& row);

/// `field` quoted for a CSV file when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& field);

}  // namespace organsmith
