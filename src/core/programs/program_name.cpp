// Program names, O numbers, first comments and the protected range (see program_name.h).
#include "cnc_bridge/programs/program_name.h"

#include <algorithm>
#include <cctype>
#include <cstdio>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/regular_file.h"

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

namespace
{
constexpr size_t kMaxCommentChars = 256;  // a title; the rest of a longer comment is not kept
constexpr size_t kFirstBlockChars = 32;   // enough to show what the number block says

bool endOfBlock(char c)
{
  return c == '\n' || c == '\r';
}

/// Characters a control skips before and between blocks: tape leader (NUL, DEL) and blanks.
bool leader(char c)
{
  return c == ' ' || c == '\t' || c == '\0' || c == '\x7f' || c == '\f' || c == '\v';
}
}  // namespace

bool HeaderScanner::feed(const char* data, size_t size)
{
  for (size_t i = 0; i < size && !done_; ++i)
    take(data[i]);
  return done_;
}

void HeaderScanner::take(char c)
{
  ++consumed_;
  if (first_block_open_ && state_ != State::kBlockStart)
  {
    if (endOfBlock(c))
      first_block_open_ = false;
    else if (header_.first_block.size() < kFirstBlockChars)
      header_.first_block.push_back(c);
  }
  switch (state_)
  {
    case State::kBlockStart:
      if (endOfBlock(c) || leader(c))
        break;
      if (c == '%')
        state_ = State::kPercent;
      else if (c == '(')
      {
        state_ = State::kComment;
        comment_return_ = State::kBlockStart;
      }
      else
      {
        // The program's first block: it holds the number if it starts with one.
        header_.first_block.push_back(c);
        first_block_open_ = true;
        if (c == 'O' || c == 'o' || c == ':')
          state_ = State::kNumberLetter;
        else
          endNumber(false, false);
      }
      break;
    case State::kPercent:
      if (endOfBlock(c))
        state_ = State::kBlockStart;
      break;
    case State::kComment:
      if (c == ')' || endOfBlock(c))  // an unclosed comment ends with its block
      {
        endComment();
        state_ = comment_return_;
      }
      else if (comment_.size() < kMaxCommentChars)
        comment_.push_back(c);
      break;
    case State::kNumberLetter:
      if (std::isdigit(static_cast<unsigned char>(c)))
      {
        digits_ = 0;
        value_ = 0;
        state_ = State::kNumberDigits;
        addDigit(c);
      }
      else if (c != ' ' && c != '\t')
      {
        endNumber(true, false);  // `O` with no digits
        text(c);
      }
      break;
    case State::kNumberDigits:
      if (std::isdigit(static_cast<unsigned char>(c)))
        addDigit(c);
      else
      {
        endNumber(true, digits_ <= kMaxDigits);
        text(c);
      }
      break;
    case State::kText:
      text(c);
      break;
  }
  const bool first_block_known = !first_block_open_ || header_.first_block.size() >= kFirstBlockChars;
  done_ = number_decided_ && first_block_known && (comment_found_ || consumed_ >= kHeaderBytes);
}

void HeaderScanner::addDigit(char c)
{
  if (++digits_ <= kMaxDigits)
    value_ = value_ * 10 + static_cast<uint32_t>(c - '0');
}

void HeaderScanner::text(char c)
{
  state_ = State::kText;
  if (c == '(' && !comment_found_)
  {
    state_ = State::kComment;
    comment_return_ = State::kText;
  }
}

void HeaderScanner::endNumber(bool numbered, bool valid)
{
  number_decided_ = true;
  state_ = State::kText;
  if (numbered && valid)
    header_.number = value_;
  header_.number_unreadable = numbered && !valid;
}

void HeaderScanner::endComment()
{
  if (!comment_found_)
  {
    header_.comment = trimmed(comment_);
    comment_found_ = true;
  }
  comment_.clear();
}

void HeaderScanner::finish()
{
  if (state_ == State::kNumberLetter)
    endNumber(true, false);
  else if (state_ == State::kNumberDigits)
    endNumber(true, digits_ <= kMaxDigits);
  else if (state_ == State::kComment)
    endComment();
  done_ = true;
}

ProgramHeader readHeader(const std::string& text)
{
  HeaderScanner scanner;
  scanner.feed(text);
  scanner.finish();
  return scanner.header();
}

ProgramHeader readHeaderOfFile(const std::string& path)
{
  RegularFile file(path);
  HeaderScanner scanner;
  char buffer[16384];
  while (!scanner.done())
  {
    const size_t n = file.read(buffer, sizeof buffer);
    if (n == 0)
      break;
    scanner.feed(buffer, n);
  }
  scanner.finish();
  return scanner.header();
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

void ProtectedRange::checkHeader(const std::string& what, const std::optional<uint32_t>& name_number,
                                 const ProgramHeader& header) const
{
  check(what, name_number, header.number);
  if (allowed_ || empty_ || !header.number_unreadable)
    return;
  throw DisabledError("refused: the program number of " + what + " cannot be read from its first block '" +
                      header.first_block + "' (O or : and 1 to 8 digits), so it cannot be checked against the " +
                      "protected range " + describe() + "; check the program's first block, or set " + switch_name_ +
                      " to send it anyway");
}

void checkProtectedFile(const ProtectedRange& range, const NamePattern& pattern, const std::string& path,
                        const std::string& sent_name)
{
  std::string name = sent_name.empty() ? path : sent_name;
  const auto slash = name.find_last_of('/');
  if (slash != std::string::npos)
    name = name.substr(slash + 1);
  range.checkHeader(path, pattern.number(name), readHeaderOfFile(path));
}
}  // namespace cnc_bridge::programs
