#include "core/csv.h"

#include <csv.h>

#include <cctype>
#include <charconv>
#include <sstream>

namespace organsmith {

int CsvTable::column(const std::string& name) const {
  for (std::size_t i = 0; i < header.fields.size(); ++i)
    if (header.fields[i] == name) return int(i);
  return -1;
}

namespace {

struct Collector {
  std::vector<CsvRow> rows;
  CsvRow current;
  int line = 0;
};

void on_field(void* bytes, std::size_t length, void* data) {
  auto* c = static_cast<Collector*>(data);
  c->current.fields.emplace_back(bytes ? static_cast<const char*>(bytes) : "", bytes ? length : 0);
}

void on_row(int, void* data) {
  auto* c = static_cast<Collector*>(data);
  c->current.line = c->line;
  c->rows.push_back(std::move(c->current));
  c->current = {};
}

}  // namespace

std::vector<CsvRow> parse_csv_rows(const std::string& text, const std::filesystem::path& source, ExitCode code) {
  csv_parser parser;
  if (csv_init(&parser, CSV_STRICT | CSV_STRICT_FINI) != 0) throw Error(code, "cannot start the CSV reader", source);
  Collector c;
  // A UTF-8 byte-order mark (what spreadsheet programs put first) is not part of the first field.
  std::istringstream in(text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? text.substr(3) : text);
  std::string line;
  bool in_quote = false;  // a quoted field spans this line break: '#' lines are data there
  auto fail = [&](const std::string& what) {
    csv_free(&parser);
    throw Error(code, what + " (line " + std::to_string(c.line) + ")", source,
                "write one row per line, fields separated by commas, quotes doubled inside quoted fields");
  };
  while (std::getline(in, line)) {
    ++c.line;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!in_quote) {
      const auto first = line.find_first_not_of(" \t");
      if (first == std::string::npos || line[first] == '#') continue;
    }
    line += '\n';
    const std::size_t before = c.rows.size();
    if (csv_parse(&parser, line.data(), line.size(), on_field, on_row, &c) != line.size())
      fail(std::string("malformed CSV: ") + csv_strerror(csv_error(&parser)));
    // libcsv holds a row open only inside a quoted field (the line break ended every other row).
    in_quote = c.rows.size() == before;
  }
  if (csv_fini(&parser, on_field, on_row, &c) != 0) fail("a quoted field is not closed");
  csv_free(&parser);
  return std::move(c.rows);
}

CsvTable parse_csv(const std::string& text, const std::filesystem::path& source, ExitCode code) {
  std::vector<CsvRow> rows = parse_csv_rows(text, source, code);
  CsvTable table;
  if (rows.empty()) throw Error(code, "the CSV file has no header row", source, "the first line names the columns");
  table.header = std::move(rows.front());
  for (std::size_t i = 1; i < rows.size(); ++i) {
    if (rows[i].fields.size() != table.header.fields.size())
      throw Error(code,
                  "line " + std::to_string(rows[i].line) + " has " + std::to_string(rows[i].fields.size()) +
                      " fields where the header has " + std::to_string(table.header.fields.size()),
                  source, "give every row one field per column (an empty field is allowed: a,,c)");
    table.rows.push_back(std::move(rows[i]));
  }
  return table;
}

std::optional<double> csv_number(std::string_view field) {
  if (!field.empty() && field.front() == '+') field.remove_prefix(1);
  double v = 0;
  const auto r = std::from_chars(field.data(), field.data() + field.size(), v);
  if (field.empty() || r.ec != std::errc() || r.ptr != field.data() + field.size()) return std::nullopt;
  return v;
}

void lowercase_fields(CsvRow& row) {
  for (auto& name : row.fields)
    for (auto& ch : name) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
}

std::string csv_field(const std::string& field) {
  if (field.find_first_of(",\"\r\n") == std::string::npos) return field;
  std::string out = "\"";
  for (char ch : field) {
    if (ch == '"') out += '"';
    out += ch;
  }
  return out + "\"";
}

}  // namespace organsmith
