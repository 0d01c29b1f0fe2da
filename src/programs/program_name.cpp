// Program names, O numbers, first comments and the protected range (see program_name.h).
#include "cnc_bridge/programs/program_name.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fstream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::programs
{
namespace
{
constexpr int kMaxDigits = 8;

bool sameLetters(const std::string& a, size_t at, const std::string& b)
{
  if (at + b.size() > a.size())
    return false;
  for (size_t i = 0; i < b.size(); ++i)
  {
    if (std::tolower(static_cast<unsigned char>(a[at + i])) != std::tolower(static_cast<unsigned char>(b[i])))
      return false;
  }
  return true;
}

/// Digits at \p at (at most kMaxDigits): the value, and how many were read.
std::optional<uint32_t> digitsAt(const std::string& text, size_t at, size_t& count)
{
  uint32_t value = 0;
  count = 0;
  while (at + count < text.size() && std::isdigit(static_cast<unsigned char>(text[at + count])))
  {
    if (++count > kMaxDigits)
      return std::nullopt;
    value = value * 10 + static_cast<uint32_t>(text[at + count - 1] - '0');
  }
  if (count == 0)
    return std::nullopt;
  return value;
}

std::string trimmed(const std::string& text)
{
  const auto first = text.find_first_not_of(" \t");
  if (first == std::string::npos)
    return "";
  return text.substr(first, text.find_last_not_of(" \t") - first + 1);
}
}  // namespace

NamePattern::NamePattern(const std::string& pattern) : text_(pattern)
{
  std::string* part = &prefix_;
  bool have_number = false;
  for (size_t i = 0; i < pattern.size(); ++i)
  {
    const char c = pattern[i];
    if (c == '/')
      throw ConfigError("program name pattern '" + pattern + "' may not contain '/'");
    if (c != '%')
    {
      part->push_back(c);
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%')
    {
      part->push_back('%');
      ++i;
      continue;
    }
    size_t j = i + 1;
    int width = 0;
    if (j < pattern.size() && pattern[j] == '0')
    {
      ++j;
      while (j < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[j])))
        width = std::min(width * 10 + (pattern[j++] - '0'), kMaxDigits + 1);  // "%0999...d" must not overflow
      if (width < 1 || width > kMaxDigits)
        throw ConfigError("program name pattern '" + pattern + "': the width of %0Nd must be 1 to 8");
    }
    if (j >= pattern.size() || pattern[j] != 'd' || have_number)
      throw ConfigError("program name pattern '" + pattern + "' must hold exactly one %d or %0Nd (e.g. O%05d.nc)");
    have_number = true;
    width_ = width;
    part = &suffix_;
    i = j;
  }
  if (!have_number)
    throw ConfigError("program name pattern '" + pattern + "' has no number field %d or %0Nd (e.g. O%05d.nc)");
}

std::string NamePattern::format(uint32_t number) const
{
  char digits[16];
  std::snprintf(digits, sizeof(digits), "%0*u", width_, number);
  return prefix_ + digits + suffix_;
}

std::optional<uint32_t> NamePattern::number(const std::string& name) const
{
  if (name.size() < prefix_.size() + suffix_.size() + 1 || !sameLetters(name, 0, prefix_))
    return std::nullopt;
  size_t count = 0;
  const auto value = digitsAt(name, prefix_.size(), count);
  if (!value || prefix_.size() + count + suffix_.size() != name.size() ||
      !sameLetters(name, prefix_.size() + count, suffix_))
    return std::nullopt;
  return value;
}

ProgramHeader readHeader(const std::string& all)
{
  const std::string text = all.substr(0, kHeaderBytes);
  ProgramHeader header;
  bool seen_block = false;  // the number only counts in the first block that is not '%' or blank
  size_t pos = 0;
  while (pos < text.size())
  {
    size_t end = text.find_first_of("\r\n", pos);
    if (end == std::string::npos)
      end = text.size();
    const std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    const std::string block = trimmed(line);
    if (block.empty() || block == "%")
      continue;
    if (!seen_block)
    {
      seen_block = true;
      if (block[0] == 'O' || block[0] == 'o' || block[0] == ':')
      {
        size_t count = 0;
        header.number = digitsAt(block, 1, count);
      }
    }
    const auto open = block.find('(');
    if (open != std::string::npos)
    {
      const auto close = block.find(')', open);
      header.comment =
          trimmed(block.substr(open + 1, close == std::string::npos ? std::string::npos : close - open - 1));
      return header;
    }
  }
  return header;
}

ProgramHeader readHeaderOfFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw Error("cannot read " + path);
  std::string head(kHeaderBytes, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  return readHeader(head);
}

std::string programLabel(uint32_t number)
{
  char text[16];
  std::snprintf(text, sizeof(text), "O%05u", number);
  return text;
}

ProtectedRange::ProtectedRange(const std::string& range, bool allowed, std::string switch_name)
    : allowed_(allowed), switch_name_(std::move(switch_name))
{
  const std::string text = trimmed(range);
  if (text.empty() || text == "none")
    return;
  const auto dash = text.find('-');
  auto number = [&](std::string part) -> uint32_t
  {
    part = trimmed(part);
    if (!part.empty() && (part[0] == 'O' || part[0] == 'o'))
      part.erase(0, 1);
    size_t count = 0;
    const auto value = digitsAt(part, 0, count);
    if (!value || count != part.size())
      throw ConfigError("protected program range '" + range + "' is not like O08000-O09999");
    return *value;
  };
  if (dash == std::string::npos)
    throw ConfigError("protected program range '" + range + "' is not like O08000-O09999");
  first_ = number(text.substr(0, dash));
  last_ = number(text.substr(dash + 1));
  if (last_ < first_)
    throw ConfigError("protected program range '" + range + "' ends before it starts");
  empty_ = false;
}

std::string ProtectedRange::describe() const
{
  return empty_ ? "none" : programLabel(first_) + "-" + programLabel(last_);
}

void ProtectedRange::check(const std::string& what, const std::optional<uint32_t>& name_number,
                           const std::optional<uint32_t>& text_number) const
{
  if (allowed_)
    return;
  for (const auto& number : {name_number, text_number})
  {
    if (number && contains(*number))
    {
      throw DisabledError("refused: " + what + " is program " + programLabel(*number) + ", in the protected range " +
                          describe() + " (probing/WIPS and OEM macros on a Haas); set " + switch_name_ +
                          " to send it anyway");
    }
  }
}

void checkProtectedFile(const ProtectedRange& range, const NamePattern& pattern, const std::string& path,
                        const std::string& sent_name)
{
  std::string name = sent_name.empty() ? path : sent_name;
  const auto slash = name.find_last_of('/');
  if (slash != std::string::npos)
    name = name.substr(slash + 1);
  range.check(path, pattern.number(name), readHeaderOfFile(path).number);
}
}  // namespace cnc_bridge::programs
