// BlockLexer: the words of one NC block, strictly for the parser or leniently for modal tracking.
#include "cnc_bridge/gcode/lexer.h"

#include <charconv>
#include <cmath>
#include <cstring>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace gcode
{
namespace
{
inline char upper(char c)
{
  return (c >= 'a' && c <= 'z') ? static_cast<char>(c - 'a' + 'A') : c;
}

inline bool isLetter(char c)
{
  const char u = upper(c);
  return u >= 'A' && u <= 'Z';
}

std::string describeChar(char c)
{
  const auto byte = static_cast<unsigned char>(c);
  if (byte >= 32 && byte < 127)
  {
    return std::string("'") + c + "'";
  }
  static const char kHex[] = "0123456789abcdef";
  return std::string("byte 0x") + kHex[byte >> 4] + kHex[byte & 15];
}

enum class Number
{
  kPlain,
  kNone,
  kOutOfRange
};

// Whether text is a plain number: optional sign, digits with at most one '.' and at least one
// digit, no exponent, nothing else.
Number plainNumber(std::string_view text, double& value, bool& decimal)
{
  const bool signed_number = !text.empty() && (text[0] == '+' || text[0] == '-');
  const std::string_view digits = text.substr(signed_number ? 1 : 0);
  const bool starts_right =
      !digits.empty() && ((digits[0] >= '0' && digits[0] <= '9') ||
                          (digits[0] == '.' && digits.size() > 1 && digits[1] >= '0' && digits[1] <= '9'));
  if (!starts_right)
  {
    return Number::kNone;
  }
  const char* const end = digits.data() + digits.size();
  const auto result = std::from_chars(digits.data(), end, value, std::chars_format::fixed);
  if (result.ec == std::errc::result_out_of_range || (result.ec == std::errc() && !std::isfinite(value)))
  {
    return Number::kOutOfRange;
  }
  if (result.ec != std::errc() || result.ptr != end)
  {
    return Number::kNone;
  }
  if (text[0] == '-')
  {
    value = -value;
  }
  decimal = digits.find('.') != std::string_view::npos;
  return Number::kPlain;
}
}  // namespace

void BlockLexer::fail(size_t index, const std::string& reason) const
{
  throw ParseError(line_, static_cast<uint32_t>(index + 1), reason);
}

bool BlockLexer::skipToWord()
{
  const bool strict = mode_ == Mode::kStrict;
  while (i_ < text_.size())
  {
    const char c = text_[i_];
    if (c == ';')
    {
      i_ = text_.size();
      return false;
    }
    if (c == '(')
    {
      const size_t open = i_;
      const size_t close = text_.find(')', open);
      const size_t nested = text_.find('(', open + 1);
      if (strict && nested < close)
      {
        fail(nested, "nested '(' inside a comment");
      }
      if (close == std::string_view::npos)
      {
        if (strict)
        {
          fail(open, "comment '(' not closed on this line");
        }
        i_ = text_.size();
        return false;
      }
      i_ = close + 1;
      continue;
    }
    if (isLetter(c))
    {
      return true;
    }
    if (strict && !isBlank(c))
    {
      if (c == '#' || c == '[' || c == '=')
      {
        fail(i_, std::string("macro expressions ('") + c + "') are not supported");
      }
      fail(i_, "unexpected character " + describeChar(c));
    }
    ++i_;
  }
  return false;
}

bool BlockLexer::next(LexedWord& word)
{
  if (!skipToWord())
  {
    return false;
  }
  word = LexedWord{};
  word.letter = upper(text_[i_]);
  word.column = static_cast<uint32_t>(i_ + 1);
  ++i_;
  if (mode_ == Mode::kStrict)
  {
    return strictNumber(word);
  }
  lenientValue(word);
  return true;
}

// Blanks may stand between the letter and its number ("X 1.5"), not inside the number.
bool BlockLexer::strictNumber(LexedWord& word)
{
  const size_t letter_index = word.column - 1;
  while (i_ < text_.size() && isBlank(text_[i_]))
  {
    ++i_;
  }
  size_t end = i_;
  if (end < text_.size() && (text_[end] == '+' || text_[end] == '-'))
  {
    ++end;
  }
  while (end < text_.size() && ((text_[end] >= '0' && text_[end] <= '9') || text_[end] == '.'))
  {
    ++end;
  }
  // The longest run of sign, digits and points; a second '.' ends the number where from_chars does.
  const auto* first_dot = static_cast<const char*>(std::memchr(text_.data() + i_, '.', end - i_));
  if (first_dot != nullptr)
  {
    const auto* second = static_cast<const char*>(
        std::memchr(first_dot + 1, '.', static_cast<size_t>(text_.data() + end - first_dot - 1)));
    if (second != nullptr)
    {
      end = static_cast<size_t>(second - text_.data());
    }
  }
  word.text = text_.substr(i_, end - i_);
  if (word.text.empty() && i_ < text_.size() && (text_[i_] == '#' || text_[i_] == '['))
  {
    fail(i_, std::string("macro expressions ('") + text_[i_] + "') are not supported");
  }
  const Number number = plainNumber(word.text, word.value, word.decimal);
  if (number != Number::kPlain)
  {
    fail(letter_index, std::string("word ") + word.letter +
                           (number == Number::kOutOfRange ? " number out of range" : " has no number"));
  }
  word.numeric = true;
  i_ = end;
  return true;
}

// To the next letter, comment, ';' or blank outside brackets: "X#100", "X[#1+2]", "G01".
void BlockLexer::lenientValue(LexedWord& word)
{
  const size_t start = i_;
  int depth = 0;
  for (; i_ < text_.size(); ++i_)
  {
    const char v = text_[i_];
    if (v == '[')
    {
      ++depth;
    }
    else if (v == ']')
    {
      depth = depth > 0 ? depth - 1 : 0;
    }
    else if (depth == 0 && (isLetter(v) || v == '(' || v == ';' || isBlank(v)))
    {
      break;
    }
  }
  word.text = text_.substr(start, i_ - start);
  word.numeric = plainNumber(word.text, word.value, word.decimal) == Number::kPlain;
}
}  // namespace gcode
}  // namespace cnc_bridge
