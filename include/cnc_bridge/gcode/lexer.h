// The words of one NC block as written: one lexer for the parser (strict: every character of the
// block is accounted for, or the block is refused with its column) and for the tools that only
// follow a program's modal words (lenient: macro expressions kept as text, what is not a word
// skipped). The syntax is the Fanuc/Haas one of docs/gcode.md: a letter, then a number;
// comments in parentheses; ';' comments out the rest of the line.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace cnc_bridge
{
namespace gcode
{
/// \brief A blank between words: space, tab, CR, FF, VT (not the end of line).
inline bool isBlank(char c)
{
  return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

/// \brief One address word.
struct LexedWord
{
  char letter = 0;        ///< upper case
  uint32_t column = 0;    ///< 1-based column of the letter
  std::string_view text;  ///< the value as written: "-1.5", "01", "#100", "[#1+2]"
  bool numeric = false;   ///< text is a plain number (sign, digits, at most one '.')
  double value = 0.0;     ///< when numeric
  bool decimal = false;   ///< when numeric: the number had a decimal point
};

/// \brief Splits one block (one line, without its end of line) into words. Not thread-safe.
///
/// Strict: throws ParseError (with \p line and the column) for an unclosed or nested comment, a
/// macro expression ('#', '[', '='), a character that starts no word, a word without a number,
/// and a number out of range. Lenient: never throws; a word's value runs to the next letter,
/// comment, ';' or blank outside brackets and is kept as text (numeric says whether it is a plain
/// number); anything else is skipped, and an unclosed comment ends the block.
///
/// The block-level marks ('%' lines, '/' block delete) are the caller's: skip them before.
class BlockLexer
{
 public:
  enum class Mode
  {
    kStrict,
    kLenient
  };

  BlockLexer(std::string_view block, Mode mode, uint32_t line = 0, size_t start = 0)
      : text_(block), mode_(mode), line_(line), i_(start)
  {
  }

  /// \brief The next word; false at the end of the block.
  bool next(LexedWord& word);

 private:
  bool skipToWord();  // past blanks and comments; false at the end
  bool strictNumber(LexedWord& word);
  void lenientValue(LexedWord& word);
  [[noreturn]] void fail(size_t index, const std::string& reason) const;

  std::string_view text_;
  Mode mode_;
  uint32_t line_;
  size_t i_;
};
}  // namespace gcode
}  // namespace cnc_bridge
