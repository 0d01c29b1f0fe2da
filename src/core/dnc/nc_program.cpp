// LineReader, the character check and the modal-state tracker behind a drip-feed restart.
#include "cnc_bridge/dnc/nc_program.h"

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/gcode/lexer.h"

namespace cnc_bridge
{
namespace dnc
{
// ---------------------------------------------------------------------------------------------
// LineReader

namespace
{
constexpr size_t kReadBufferSize = size_t{64} * 1024;
}

LineReader::LineReader(const std::string& path, size_t max_line_length)
    : path_(path), max_line_length_(max_line_length), file_(std::fopen(path.c_str(), "rb")), buffer_(kReadBufferSize)
{
  if (file_ == nullptr)
  {
    throw ConfigError("cannot open program " + path + ": " + std::strerror(errno));
  }
  struct stat info;
  if (::fstat(::fileno(file_), &info) == 0)
  {
    if (S_ISDIR(info.st_mode))
    {
      std::fclose(file_);
      file_ = nullptr;
      throw ConfigError("program " + path + " is a directory");
    }
    file_size_ = static_cast<uint64_t>(info.st_size);
  }
}

LineReader::~LineReader()
{
  if (file_ != nullptr)
  {
    std::fclose(file_);
  }
}

int LineReader::fill()
{
  if (pos_ == end_)
  {
    end_ = std::fread(buffer_.data(), 1, buffer_.size(), file_);
    pos_ = 0;
    if (end_ == 0)
    {
      if (std::ferror(file_))
      {
        throw Error("cannot read program " + path_ + ": " + std::strerror(errno));
      }
      return -1;
    }
  }
  return static_cast<unsigned char>(buffer_[pos_++]);
}

bool LineReader::next(std::string& line)
{
  line.clear();
  int c = fill();
  if (c < 0)
  {
    return false;
  }
  ++line_number_;
  while (c >= 0 && c != '\n' && c != '\r')
  {
    if (line.size() >= max_line_length_)
    {
      throw ConfigError("program " + path_ + " line " + std::to_string(line_number_) + " is longer than " +
                        std::to_string(max_line_length_) + " characters (not an NC program?)");
    }
    line.push_back(static_cast<char>(c));
    c = fill();
  }
  if (c == '\r')
  {
    // CR LF is one line end; a CR alone (old Mac files, EIA punches) is one too.
    const int after = fill();
    if (after >= 0 && after != '\n')
    {
      --pos_;  // fill() just loaded or advanced within the buffer, so the byte is still there
    }
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Character check

std::string CharacterIssue::describe() const
{
  std::ostringstream out;
  char hex[8];
  std::snprintf(hex, sizeof(hex), "0x%02X", byte);
  out << "line " << line << " column " << column << ": ";
  if (byte >= 0x20 && byte < 0x7F)
  {
    out << "'" << static_cast<char>(byte) << "' (" << hex << ")";
  }
  else
  {
    out << hex;
  }
  out << " " << reason;
  return out.str();
}

void checkLine(const std::string& line, uint64_t line_number, const CharacterRules& rules,
               std::vector<CharacterIssue>& out, size_t limit)
{
  for (size_t i = 0; i < line.size() && out.size() < limit; ++i)
  {
    const auto byte = static_cast<uint8_t>(line[i]);
    const char* reason = nullptr;
    if (byte >= 0x80)
    {
      reason = "is not ASCII (the control takes 7-bit characters)";
    }
    else if (byte == 0x11 || byte == 0x12 || byte == 0x13 || byte == 0x14)
    {
      reason = "is a DC code: it would start or stop the reader in the middle of the program";
    }
    else if ((byte < 0x20 && byte != '\t') || byte == 0x7F)
    {
      reason = "is a control character";
    }
    else if (rules.reject_lowercase && byte >= 'a' && byte <= 'z')
    {
      reason = "is lowercase (not in the ISO code the control reads; set lowercase allowed for 8N1 controls)";
    }
    if (reason != nullptr)
    {
      out.push_back(CharacterIssue{line_number, i + 1, byte, reason});
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Words and modal state

namespace
{
struct Word
{
  char letter;
  std::string value;  // as written: "01", "54.1", "[#1+2]"
  double number;      // the value when it is a plain number, else NaN (an expression, or nothing)
};

// The address words of a block, through the G-code parser's lexer in its lenient mode: comments
// and anything after ';' left out, macro expressions kept as text.
std::vector<Word> splitWords(const std::string& line)
{
  std::vector<Word> words;
  gcode::BlockLexer lexer(line, gcode::BlockLexer::Mode::kLenient);
  gcode::LexedWord word;
  while (lexer.next(word))
  {
    words.push_back(Word{word.letter, std::string(word.text), word.numeric ? word.value : std::nan("")});
  }
  return words;
}

bool is(double value, double code)
{
  return std::fabs(value - code) < 1e-6;
}

std::string word(char letter, const std::string& value)
{
  return std::string(1, letter) + value;
}

// "N01234" and "1234" both become "1234" (Fanuc ignores leading zeros of a sequence number).
std::string normaliseSequence(std::string text)
{
  if (!text.empty() && (text[0] == 'N' || text[0] == 'n'))
  {
    text.erase(0, 1);
  }
  const size_t nonzero = text.find_first_not_of('0');
  return nonzero == std::string::npos ? (text.empty() ? text : "0") : text.substr(nonzero);
}
}  // namespace

std::string sequenceNumber(const std::string& line)
{
  for (const auto& w : splitWords(line))
  {
    if (w.letter == 'N' && !w.value.empty())
    {
      return "N" + w.value;
    }
    break;  // a sequence number is the first word of a block
  }
  return "";
}

// What one block says beyond the modal groups it sets at once: words that complete others (H for
// G43, P for G54.1) and the tool change, settled once the whole block is read.
struct ModalTracker::Block
{
  std::string h_word;
  std::string p_word;
  std::string t_here;
  bool has_m6 = false;
  bool g54_1 = false;
  bool g43 = false;
};

void ModalTracker::apply(const std::string& line)
{
  const auto words = splitWords(line);
  Block block;
  for (const auto& w : words)
  {
    if (w.letter == 'H')
    {
      block.h_word = word('H', w.value);
    }
    else if (w.letter == 'P')
    {
      block.p_word = word('P', w.value);
    }
  }
  for (const auto& w : words)
  {
    switch (w.letter)
    {
      case 'N':
        state_.sequence = word('N', w.value);
        break;
      case 'F':
        state_.feed = word('F', w.value);
        break;
      case 'S':
        state_.spindle_speed = word('S', w.value);
        break;
      case 'T':
        block.t_here = word('T', w.value);
        last_t_ = block.t_here;
        break;
      case 'G':
        applyG(w.number, block);
        break;
      case 'M':
        applyM(w.number, block);
        break;
      default:
        break;
    }
  }
  settle(block);
}

void ModalTracker::applyG(double v, Block& block)
{
  if (is(v, 0) || is(v, 1) || is(v, 2) || is(v, 3))
  {
    state_.motion = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 17) || is(v, 18) || is(v, 19))
  {
    state_.plane = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 20) || is(v, 21))
  {
    state_.units = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 90) || is(v, 91))
  {
    state_.distance = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 54.1))
  {
    block.g54_1 = true;
  }
  else if ((v >= 54 && v <= 59 && is(v, std::round(v))) || (v >= 110 && v <= 129 && is(v, std::round(v))))
  {
    state_.work_offset = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 43) || is(v, 44))
  {
    block.g43 = true;
    state_.tool_length = "G" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 49))
  {
    state_.tool_length = "G49";
  }
}

void ModalTracker::applyM(double v, Block& block)
{
  if (is(v, 3) || is(v, 4) || is(v, 5))
  {
    state_.spindle = "M" + std::to_string(static_cast<int>(v));
  }
  else if (is(v, 6))
  {
    block.has_m6 = true;
  }
  else if (is(v, 7) || is(v, 8) || is(v, 9))
  {
    state_.coolant = "M" + std::to_string(static_cast<int>(v));
  }
}

void ModalTracker::settle(const Block& block)
{
  if (block.g54_1)
  {
    state_.work_offset = block.p_word.empty() ? "G54.1" : "G54.1 " + block.p_word;
  }
  if (block.g43 && !block.h_word.empty())
  {
    state_.tool_length += " " + block.h_word;
  }
  if (block.has_m6)
  {
    // "T5 M6" and "M6 T5" change to T5; "M6" alone changes to the T selected earlier.
    state_.tool = block.t_here.empty() ? last_t_ : block.t_here;
    pending_m6_ = true;
  }
  else if (!pending_m6_ && !block.t_here.empty())
  {
    // No M6 in the program so far: a lathe-style T0101 indexes the turret by itself.
    state_.tool = block.t_here;
  }
}

std::string ModalTracker::restartPreamble(uint64_t line_number, std::vector<std::string>* warnings) const
{
  std::ostringstream out;
  out << "(RESTART AT LINE " << line_number << ")\n";
  std::string setup;
  for (const std::string* part : {&state_.units, &state_.plane, &state_.distance, &state_.work_offset})
  {
    if (!part->empty())
    {
      setup += (setup.empty() ? "" : " ") + *part;
    }
  }
  if (!setup.empty())
  {
    out << setup << "\n";
  }
  if (!state_.tool.empty())
  {
    out << state_.tool << (pending_m6_ ? " M6" : "") << "\n";
  }
  if (!state_.tool_length.empty())
  {
    out << state_.tool_length << "\n";
  }
  if (!state_.spindle_speed.empty() || !state_.spindle.empty())
  {
    std::string spindle = state_.spindle_speed;
    if (!state_.spindle.empty())
    {
      spindle += (spindle.empty() ? "" : " ") + state_.spindle;
    }
    out << spindle << "\n";
  }
  if (!state_.coolant.empty())
  {
    out << state_.coolant << "\n";
  }
  std::string motion = state_.motion;
  if (motion == "G2" || motion == "G3")
  {
    if (warnings != nullptr)
    {
      warnings->push_back("an arc (" + motion + ") was active before line " + std::to_string(line_number) +
                          ": restated as G1; check that the restart block has its own motion code");
    }
    motion = "G1";
  }
  if (!state_.feed.empty())
  {
    motion += (motion.empty() ? "" : " ") + state_.feed;
  }
  if (!motion.empty())
  {
    out << motion << "\n";
  }
  return out.str();
}

// ---------------------------------------------------------------------------------------------
// Scan

namespace
{
bool blank(const std::string& line)
{
  return line.find_first_not_of(" \t") == std::string::npos;
}

bool percentLine(const std::string& line)
{
  const size_t first = line.find_first_not_of(" \t");
  return first != std::string::npos && line[first] == '%' &&
         line.find_first_not_of(" \t", first + 1) == std::string::npos;
}
}  // namespace

namespace
{
/// Counts \p issue; the first 100 are kept with their line and column.
void addIssue(ProgramScan& scan, CharacterIssue issue)
{
  ++scan.issue_count;
  if (scan.issues.size() < 100)
  {
    scan.issues.push_back(std::move(issue));
  }
}
}  // namespace

ProgramScan scanProgram(const std::string& path, const CharacterRules& rules, const RestartPoint& restart,
                        size_t eob_size, size_t max_line_length)
{
  ProgramScan scan;
  LineReader reader(path, max_line_length);
  ModalTracker tracker;
  const std::string wanted_block = restart.block.empty() ? "" : normaliseSequence(restart.block);
  bool found = !restart.active();
  uint64_t percent_pending = 0;  // a '%' line after the first text line, not yet known to be the last
  uint64_t body_through_last_text = 0;
  uint64_t body = 0;
  std::string line;
  std::vector<CharacterIssue> line_issues;
  while (reader.next(line))
  {
    const uint64_t n = reader.lineNumber();
    line_issues.clear();
    checkLine(line, n, rules, line_issues);
    for (auto& issue : line_issues)
    {
      addIssue(scan, std::move(issue));
    }
    const bool text = !blank(line);
    if (text)
    {
      if (scan.first_text_line == 0)
      {
        scan.first_text_line = n;
        scan.starts_with_percent = percentLine(line);
      }
      else
      {
        if (percent_pending != 0 && rules.reject_inner_percent)
        {
          addIssue(scan, CharacterIssue{percent_pending, 1, '%',
                                        "ends the program at the control, but more program follows"});
        }
        percent_pending = 0;
        if (percentLine(line))
        {
          percent_pending = n;
        }
        else if (rules.reject_inner_percent && line.find('%') != std::string::npos)
        {
          addIssue(scan, CharacterIssue{n, line.find('%') + 1, '%', "inside a block ends the program"});
        }
      }
      scan.last_text_line = n;
    }
    if (!found)
    {
      const bool hit = restart.line > 0 ? n == restart.line
                                        : (text && normaliseSequence(sequenceNumber(line)) == wanted_block &&
                                           !sequenceNumber(line).empty());
      if (hit)
      {
        found = true;
        scan.start_line = n;
        scan.state_at_start = tracker.state();
        scan.computed_preamble = tracker.restartPreamble(n, &scan.warnings);
      }
      else
      {
        tracker.apply(line);
      }
    }
    if (found)
    {
      body += line.size() + eob_size;
      if (text)
      {
        body_through_last_text = body;
      }
    }
  }
  scan.lines = reader.lineNumber();
  scan.ends_with_percent = percent_pending != 0 && percent_pending == scan.last_text_line;
  if (!found)
  {
    if (restart.line > 0)
    {
      throw ConfigError("restart line " + std::to_string(restart.line) + " is past the end of " + path + " (" +
                        std::to_string(scan.lines) + " lines)");
    }
    throw ConfigError("no block " + restart.block + " in " + path);
  }
  scan.body_bytes = body_through_last_text;
  return scan;
}
}  // namespace dnc
}  // namespace cnc_bridge
