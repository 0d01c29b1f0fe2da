// Unit tests of the block lexer shared by the G-code parser (strict) and the drip feed's modal
// tracker (lenient).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/gcode/lexer.h"

using namespace cnc_bridge::gcode;

namespace
{
struct Lexed
{
  char letter;
  std::string text;
  bool numeric;
  double value;
  uint32_t column;
};

std::vector<Lexed> lex(const std::string& block, BlockLexer::Mode mode)
{
  std::vector<Lexed> out;
  BlockLexer lexer(block, mode, 7);
  LexedWord word;
  while (lexer.next(word))
  {
    out.push_back({word.letter, std::string(word.text), word.numeric, word.value, word.column});
  }
  return out;
}

ParseError strictError(const std::string& block)
{
  try
  {
    lex(block, BlockLexer::Mode::kStrict);
  }
  catch (const ParseError& e)
  {
    return e;
  }
  ADD_FAILURE() << "no error for " << block;
  return ParseError(0, 0, "");
}
}  // namespace

TEST(BlockLexer, StrictReadsLettersNumbersAndColumnsPastCommentsAndBlanks)
{
  const auto words = lex("n10 G01 (go) X -1.5Y.25 z3. ; rest ignored X9", BlockLexer::Mode::kStrict);
  ASSERT_EQ(5u, words.size());
  EXPECT_EQ('N', words[0].letter);
  EXPECT_EQ(1u, words[0].column);
  EXPECT_EQ("01", words[1].text);
  EXPECT_DOUBLE_EQ(1.0, words[1].value);
  EXPECT_EQ('X', words[2].letter);
  EXPECT_EQ(14u, words[2].column);
  EXPECT_DOUBLE_EQ(-1.5, words[2].value);  // a blank between the letter and its number is allowed
  EXPECT_DOUBLE_EQ(0.25, words[3].value);
  EXPECT_EQ('Z', words[4].letter);
  EXPECT_DOUBLE_EQ(3.0, words[4].value);
}

TEST(BlockLexer, StrictRefusesWhatIsNotAWordWithItsColumn)
{
  struct Case
  {
    std::string block;
    uint32_t column;
    const char* reason_part;
  };
  const Case cases[] = {
      {"G1 X1 (a (b) c)", 10, "nested"},
      {"G1 X1 (open", 7, "not closed"},
      {"X#100", 2, "macro"},
      {"X [1+2]", 3, "macro"},
      {"#1=5", 1, "macro"},
      {"G1 X", 4, "no number"},
      {"G1 X-", 4, "no number"},
      {"G1 X--1", 4, "no number"},
      {"G1 X.", 4, "no number"},
      {"G1 X1..2", 7, "unexpected character '.'"},
      {"G1 X1 @", 7, "unexpected character '@'"},
      {"X" + std::string(400, '9'), 1, "out of range"},
  };
  for (const Case& c : cases)
  {
    SCOPED_TRACE(c.block);
    const ParseError e = strictError(c.block);
    EXPECT_EQ(7u, e.line());
    EXPECT_EQ(c.column, e.column());
    EXPECT_NE(e.reason().find(c.reason_part), std::string::npos) << e.reason();
  }
}

TEST(BlockLexer, LenientKeepsExpressionsAsTextAndSkipsWhatIsNoWord)
{
  const auto words = lex("#100=5 G01 X[#1+2] Y#2 (no close", BlockLexer::Mode::kLenient);
  ASSERT_EQ(3u, words.size());
  EXPECT_EQ('G', words[0].letter);
  EXPECT_TRUE(words[0].numeric);
  EXPECT_DOUBLE_EQ(1.0, words[0].value);
  EXPECT_EQ("[#1+2]", words[1].text);
  EXPECT_FALSE(words[1].numeric);
  EXPECT_EQ("#2", words[2].text);
  EXPECT_FALSE(words[2].numeric);
}

TEST(BlockLexer, LenientStopsAValueAtALetterCommentSemicolonOrBlankOutsideBrackets)
{
  const auto words = lex("G54.1P3X[1 + 2](c)T5;M6", BlockLexer::Mode::kLenient);
  ASSERT_EQ(4u, words.size());
  EXPECT_EQ("54.1", words[0].text);
  EXPECT_DOUBLE_EQ(54.1, words[0].value);
  EXPECT_EQ("3", words[1].text);
  EXPECT_EQ("[1 + 2]", words[2].text);  // blanks inside brackets belong to the expression
  EXPECT_EQ('T', words[3].letter);
  EXPECT_EQ("5", words[3].text);
}
