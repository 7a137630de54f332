// CSV tables (core/csv.h): RFC 4180 quoting, line numbers in errors, and the writer's quoting.
#include "core/csv.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace organsmith;

TEST(Csv, ReadsQuotedFieldsCommentsAndLineNumbers) {
  const std::string text =
      "# a comment\n"
      "id,input,note\n"
      "\n"
      "a, /data/x ,\"has, a comma\"\n"
      "b,phantom,\"two\nlines\"\n"
      "c,\"q\"\"uote\",\r\n";
  const CsvTable t = parse_csv(text, "t.csv", ExitCode::case_file);
  ASSERT_EQ(t.header.fields, (std::vector<std::string>{"id", "input", "note"}));
  EXPECT_EQ(t.header.line, 2);
  ASSERT_EQ(t.rows.size(), 3u);
  EXPECT_EQ(t.rows[0].fields[1], "/data/x");  // spaces around an unquoted field are dropped
  EXPECT_EQ(t.rows[0].fields[2], "has, a comma");
  EXPECT_EQ(t.rows[0].line, 4);
  EXPECT_EQ(t.rows[1].fields[2], "two\nlines");
  EXPECT_EQ(t.rows[1].line, 6);  // the line where the row ends
  EXPECT_EQ(t.rows[2].fields[1], "q\"uote");
  EXPECT_EQ(t.rows[2].fields[2], "");
  EXPECT_EQ(t.column("input"), 1);
  EXPECT_EQ(t.column("missing"), -1);
}

// Spreadsheet programs begin their CSV with a UTF-8 byte-order mark: it is not part of the first
// column's name (nor of a first data field when a file has no header).
TEST(Csv, AByteOrderMarkIsNotPartOfTheFirstField) {
  const CsvTable t = parse_csv("\xEF\xBB\xBFx,y\r\n1,2\r\n", "bom.csv", ExitCode::case_file);
  ASSERT_EQ(t.header.fields, (std::vector<std::string>{"x", "y"}));
  EXPECT_EQ(t.column("x"), 0);
  EXPECT_EQ(t.header.line, 1);
  EXPECT_EQ(parse_csv_rows("\xEF\xBB\xBF" "1.5,2\n", "bom.csv", ExitCode::case_file).front().fields.front(), "1.5");
  // Only at the start: elsewhere the bytes are data.
  EXPECT_EQ(parse_csv("x\n\xEF\xBB\xBF" "a\n", "bom.csv", ExitCode::case_file).rows.front().fields.front(), "\xEF\xBB\xBF" "a");
}

TEST(Csv, RejectsRaggedRowsAndOpenQuotesNamingTheLine) {
  auto message = [](const std::string& text) -> std::string {
    try {
      parse_csv(text, "bad.csv", ExitCode::case_file);
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::case_file);
      EXPECT_EQ(e.path(), "bad.csv");
      return e.message();
    }
    return "no error";
  };
  EXPECT_NE(message("a,b\n1,2\n3\n").find("line 3 has 1 fields where the header has 2"), std::string::npos);
  EXPECT_NE(message("a,b\n1,\"open\n").find("not closed"), std::string::npos);
  EXPECT_NE(message("a,b\n1,x\"y\n").find("malformed CSV"), std::string::npos);  // a quote inside an unquoted field
  EXPECT_NE(message("# only a comment\n").find("no header"), std::string::npos);
}

TEST(Csv, WriterQuotesOnlyWhatNeedsIt) {
  EXPECT_EQ(csv_field("plain"), "plain");
  EXPECT_EQ(csv_field("a,b"), "\"a,b\"");
  EXPECT_EQ(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
  const CsvTable t = parse_csv("x,y\n" + csv_field("a,\"b\"\nc") + ",2\n", "", ExitCode::case_file);
  EXPECT_EQ(t.rows.at(0).fields[0], "a,\"b\"\nc");  // the reader gives back what the writer wrote
}

TEST(Csv, RowsKeepTheirLengthAndNumbersAreWholeFields) {
  // The row reader leaves ragged rows to its caller (the calibration reader words its own error).
  const auto rows = parse_csv_rows("a,b,c\n\n1,2\n# note\n3,4,5,6\n", "r.csv", ExitCode::case_file);
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[1].fields.size(), 2u);
  EXPECT_EQ(rows[1].line, 3);
  EXPECT_EQ(rows[2].fields.size(), 4u);
  EXPECT_EQ(rows[2].line, 5);
  EXPECT_EQ(csv_number("1.25").value_or(0), 1.25);
  EXPECT_EQ(csv_number("+2e3").value_or(0), 2000.0);
  EXPECT_EQ(csv_number("-0.5").value_or(0), -0.5);
  EXPECT_TRUE(std::isnan(csv_number("nan").value_or(0)));  // parsed: finiteness is the caller's check
  for (const char* bad : {"", "1.5abc", "abc", "1,5", "0x10", "++1", "1 2"})
    EXPECT_FALSE(csv_number(bad).has_value()) << bad;
  CsvRow header{1, {"Stretch", "STRESS_Pa"}};
  lowercase_fields(header);
  EXPECT_EQ(header.fields, (std::vector<std::string>{"stretch", "stress_pa"}));
}
