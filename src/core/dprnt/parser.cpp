// LineParser: DPRNT lines to label/value pairs (grammar in the header). One pass, no regular
// expressions and no allocation beyond the labels themselves (short labels stay in the small-string
// buffer), so a core parses well over a million lines per second.
#include "cnc_bridge/dprnt/parser.h"

#include <charconv>

namespace cnc_bridge
{
namespace dprnt
{
namespace
{
inline bool isDigit(char c)
{
  return c >= '0' && c <= '9';
}
inline bool isSpace(char c)
{
  return c == ' ' || c == '\t';
}

// Copies raw label text to out with runs of spaces collapsed and the trailing filler removed.
void cleanLabel(std::string_view raw, std::string& out)
{
  out.clear();
  bool space = false;
  for (char c : raw)
  {
    if (isSpace(c))
    {
      space = !out.empty();
      continue;
    }
    if (space)
    {
      out.push_back(' ');
      space = false;
    }
    out.push_back(c);
  }
  // Trailing "=", ":" and the word "IS" join a label to its value: "Z OFFSET IS", "PARTS=".
  for (;;)
  {
    while (!out.empty() && (out.back() == '=' || out.back() == ':' || out.back() == ' '))
    {
      out.pop_back();
    }
    const size_t n = out.size();
    if (n >= 3 && out[n - 1] == 'S' && out[n - 2] == 'I' && out[n - 3] == ' ')
    {
      out.resize(n - 3);
      continue;
    }
    if (n == 2 && out == "IS")
    {
      out.clear();
    }
    break;
  }
  // An NC address or a variable name right before the number is the label on its own:
  // "PROBE X 1.5" is X, "RESULT #5223 -0.01" is #5223; "Z OFFSET" stays whole.
  const size_t last_space = out.rfind(' ');
  if (last_space != std::string::npos)
  {
    const std::string_view last(out.data() + last_space + 1, out.size() - last_space - 1);
    if (last.size() == 1 || last[0] == '#')
    {
      out.erase(0, last_space + 1);
    }
  }
}
}  // namespace

size_t LineParser::parse(std::string_view line, std::vector<LabeledValue>& out)
{
  size_t count = 0;
  size_t label_start = 0;
  const size_t n = line.size();
  size_t i = 0;
  while (i < n)
  {
    const char c = line[i];
    // '#' followed by digits is a variable name: part of the label.
    if (c == '#')
    {
      ++i;
      while (i < n && isDigit(line[i]))
        ++i;
      continue;
    }
    size_t start = i;
    size_t digits_at = i;
    bool negative = false;
    if (c == '+' || c == '-')
    {
      negative = c == '-';
      digits_at = i + 1;
      while (digits_at < n && isSpace(line[digits_at]))
        ++digits_at;
    }
    const bool starts_number =
        digits_at < n &&
        (isDigit(line[digits_at]) || (line[digits_at] == '.' && digits_at + 1 < n && isDigit(line[digits_at + 1])));
    // Digits glued to a word are its value ("X1.5", "O0110" -> O = 110); digits right after '#'
    // were consumed above as a variable name.
    if (!starts_number)
    {
      ++i;
      continue;
    }
    size_t end = digits_at;
    while (end < n && isDigit(line[end]))
      ++end;
    if (end < n && line[end] == '.')
    {
      ++end;
      while (end < n && isDigit(line[end]))
        ++end;
    }
    double value = 0.0;
    const char* first = line.data() + digits_at;
    const char* last = line.data() + end;
    std::from_chars(first, last, value);  // the text is digits [. digits]: cannot fail
    if (count == out.size())
    {
      out.emplace_back();
    }
    LabeledValue& entry = out[count++];
    cleanLabel(line.substr(label_start, start - label_start), entry.label);
    entry.value = negative ? -value : value;
    i = end;
    label_start = end;
  }
  out.resize(count);
  return count;
}

const LabeledValue* findLabel(const std::vector<LabeledValue>& values, std::string_view label)
{
  for (const auto& v : values)
  {
    if (v.label == label)
    {
      return &v;
    }
  }
  return nullptr;
}
}  // namespace dprnt
}  // namespace cnc_bridge
