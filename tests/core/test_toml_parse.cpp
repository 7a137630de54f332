// The TOML wrapper's shield against toml++ 3.3's unclassified code points (core/toml_parse.h).
#include "core/toml_parse.h"

#include <gtest/gtest.h>

namespace organsmith {
namespace {

TEST(TomlParse, TheShieldedCodePointsAreTheThreeBlocksTomlPlusPlusLeavesUnhandled) {
  const auto& list = toml_text::unsafe_list();
  ASSERT_EQ(list.size(), 3019u);
  EXPECT_EQ(list.front(), U'\u00A1');
  EXPECT_EQ(list.back(), U'\uFEFE');
  // Whitespace itself (U+00A0, U+3000, U+FEFF and the U+2000 block) is classified by toml++.
  for (const char32_t ws : {U'\u00A0', U'\u3000', U'\uFEFF', U'\u2000', U'\u1680'}) EXPECT_FALSE(toml_text::unsafe(ws));
  EXPECT_TRUE(toml_text::unsafe(U'\u00E4'));  // ä
  EXPECT_TRUE(toml_text::unsafe(U'\u2FFF'));
  EXPECT_FALSE(toml_text::unsafe(U'\u4E2D'));  // 中: a block toml++ rejects as non-whitespace
  // Every stand-in is a private-use code point, and every one comes back.
  for (std::size_t k = 0; k < list.size(); ++k) {
    std::string s;
    toml_text::append_utf8(s, list[k]);
    const std::string shielded = toml_text::shield("a" + s + "b");
    std::size_t len = 0;
    EXPECT_EQ(toml_text::decode_bmp(shielded, 1, len), toml_text::kPrivateFirst + k);
    ASSERT_EQ(toml_text::unshield(shielded), "a" + s + "b") << "U+" << std::hex << unsigned(list[k]);
  }
}

TEST(TomlParse, AByteOrderMarkBeforeTheFirstKeyIsDropped) {
  const toml::table t = parse_toml("\xEF\xBB\xBF[case]\nname = \"x\"\n", "bom.toml", "the case file", "");
  EXPECT_EQ(t["case"]["name"].value_or(std::string()), "x");
}

TEST(TomlParse, MalformedUtf8IsLeftForTheParserToRefuse) {
  const std::string bad = "x = \"\xc3\" \xe2\x82 \xed\xa0\x80\n";  // cut sequences and a surrogate
  EXPECT_EQ(toml_text::shield(bad), bad);
  EXPECT_THROW(parse_toml(bad, "bad.toml", "the file", ""), CaseFileError);
}

TEST(TomlParse, KeysStringsArraysAndMessagesAreRestored) {
  const toml::table t = parse_toml("\"k\xc3\xa4\" = [\"\xef\xb9\xb0\", { \"\xc3\xa9\" = \"\xe2\xbe\x80\" }]\n", "t.toml",
                                   "the file", "");
  const auto* arr = t["k\xc3\xa4"].as_array();
  ASSERT_NE(arr, nullptr);
  EXPECT_EQ(arr->at(0).value_or(std::string()), "\xef\xb9\xb0");
  EXPECT_EQ((*arr->at(1).as_table())["\xc3\xa9"].value_or(std::string()), "\xe2\xbe\x80");
  try {
    parse_toml("a = \xc3\xa4\n", "t.toml", "the file", "");
    FAIL() << "a bare ä was accepted";
  } catch (const CaseFileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("line 1"), std::string::npos) << what;
    EXPECT_EQ(what.find("\xee"), std::string::npos) << "a stand-in leaked into: " << what;
  }
}

}  // namespace
}  // namespace organsmith
