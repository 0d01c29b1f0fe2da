// CommandedPosition: the end point of the last motion block fed to the control, and which of its
// axes the host can know (include/cnc_bridge/dnc/commanded_position.h).
#include "cnc_bridge/dnc/commanded_position.h"

#include <cmath>
#include <exception>
#include <vector>

#include "cnc_bridge/gcode/lexer.h"

namespace cnc_bridge
{
namespace dnc
{
namespace
{
constexpr size_t kX = 0, kY = 1, kZ = 2;

bool is(double value, double code)
{
  return std::fabs(value - code) < 1e-6;
}

gcode::ParserOptions parserOptions(gcode::Dialect dialect)
{
  gcode::ParserOptions options;
  options.dialect = dialect;
  return options;
}

// G words of a refused line that still apply, restated alone to the parser so that the modal
// state the next blocks are read in stays the control's (a refused "G20 G65 P9000" is still inch).
struct ModalWord
{
  double code;
  const char* block;
};
constexpr ModalWord kModalWords[] = {{0, "G0"},   {1, "G1"},   {17, "G17"}, {18, "G18"}, {19, "G19"}, {20, "G20"},
                                     {21, "G21"}, {80, "G80"}, {90, "G90"}, {91, "G91"}, {98, "G98"}, {99, "G99"}};
// G words of a refused line that change nothing the position depends on (dwell, offsets the
// control applies, compensation off, feed mode, path hints).
constexpr double kNeutralWords[] = {4, 40, 43, 49, 54, 55, 56, 57, 58, 59, 61, 64, 94};
}  // namespace

/// What a line says, read with the lenient lexer (it never throws), whatever the parser makes of it.
struct CommandedPosition::Words
{
  std::array<bool, 3> axes{};  ///< X, Y, Z named
  bool block_delete = false;   ///< the line starts with '/'
  bool machine = false;        ///< G53, G28 or G30: numbers outside the program's frame
  bool reference = false;      ///< G28 or G30
  bool g92 = false;            ///< G92: the axes it names are re-zeroed
  bool g92_cancel = false;     ///< G92.1
  bool call = false;           ///< M98 or M97: the control runs blocks the host does not see
  bool unfollowable = false;   ///< a G word neither restated nor neutral (for a refused line)
  std::vector<const char*> modal;

  explicit Words(std::string_view line)
  {
    size_t start = 0;
    while (start < line.size() && gcode::isBlank(line[start]))
      ++start;
    block_delete = start < line.size() && line[start] == '/';
    gcode::BlockLexer lexer(line, gcode::BlockLexer::Mode::kLenient, 0, block_delete ? start + 1 : start);
    gcode::LexedWord word;
    while (lexer.next(word))
    {
      if (word.letter == 'X' || word.letter == 'Y' || word.letter == 'Z')
        axes[static_cast<size_t>(word.letter - 'X')] = true;
      else if (word.letter == 'M' && word.numeric && (is(word.value, 97) || is(word.value, 98)))
        call = true;
      else if (word.letter == 'G')
        readG(word);
    }
  }

  bool anyAxis() const { return axes[kX] || axes[kY] || axes[kZ]; }

 private:
  void readG(const gcode::LexedWord& word)
  {
    if (!word.numeric)
    {
      unfollowable = true;  // G[#1]: a mode nobody here can tell
      return;
    }
    const double g = word.value;
    machine |= is(g, 53) || is(g, 28) || is(g, 30);
    reference |= is(g, 28) || is(g, 30);
    g92 |= is(g, 92);
    g92_cancel |= is(g, 92.1);
    for (const auto& m : kModalWords)
    {
      if (is(g, m.code))
      {
        modal.push_back(m.block);
        return;
      }
    }
    for (double neutral : kNeutralWords)
    {
      if (is(g, neutral))
        return;
    }
    unfollowable = true;
  }
};

CommandedPosition::CommandedPosition(gcode::Dialect dialect) : dialect_(dialect), parser_(parserOptions(dialect)) {}

void CommandedPosition::reset()
{
  parser_.reset();
  known_ = {};
  shifted_ = {};
  pending_.clear();
  overlong_ = false;
  motion_blocks_ = 0;
  lines_ = 0;
  refused_ = 0;
  last_refusal_.clear();
}

void CommandedPosition::feedBytes(std::string_view bytes)
{
  for (const char c : bytes)
  {
    if (c == '\n' || c == '\r')
    {
      if (overlong_)
      {
        // Only part of it was kept: what it did cannot be told.
        ++lines_;
        ++refused_;
        last_refusal_ = "a line longer than " + std::to_string(parser_.options().max_line_length) + " bytes";
        forgetAll();
      }
      else if (!pending_.empty())
      {
        feedLine(pending_);
      }
      pending_.clear();
      overlong_ = false;
    }
    else if (static_cast<unsigned char>(c) < 0x20 && c != '\t')
    {
      continue;  // DC2/DC4 around the program, leader NULs: not part of a block
    }
    else if (pending_.size() < parser_.options().max_line_length)
    {
      pending_ += c;
    }
    else
    {
      overlong_ = true;
    }
  }
}

void CommandedPosition::feedLine(std::string_view line)
{
  ++lines_;
  const Words words(line);
  try
  {
    follow(parser_.parseLine(line), words);
  }
  catch (const std::exception& e)
  {
    // A block the parser cannot read must never stop the feed it is watching: the parser's state
    // is as before the line (gcode.h), and refuse() decides what is still known.
    refuse(words, e.what());
  }
}

void CommandedPosition::follow(const gcode::Block& block, const Words& words)
{
  if (words.g92)
  {
    // G92 makes the current numbers the given ones: from an unknown position, every number the
    // program writes afterwards is in a frame nobody here can place.
    for (size_t a = 0; a < 3; ++a)
      shifted_[a] = shifted_[a] || (words.axes[a] && !known_[a]);
  }
  if (words.g92_cancel)
    shifted_ = {};
  // A block that names an axis moves the tool there, even where the parser has no move for it (the
  // target is where the parser already had the tool, as a block from an unknown place can be).
  // Not G92 (it sets numbers, nothing moves) nor a dwell (Fanuc's G04 X is seconds).
  const bool motion = !block.moves.empty() || (words.anyAxis() && !words.g92 && block.dwell_s < 0);
  if (motion)
  {
    ++motion_blocks_;
    const gcode::ModalState& state = parser_.state();
    const bool absolute = state.distance == gcode::DistanceMode::kAbsolute;
    const bool cycle = block.moves.empty() ? state.canned_cycle != 0 : block.moves.front().cycle != 0;
    for (size_t a = 0; a < 3; ++a)
    {
      if (cycle && a == kZ)
      {
        // A cycle ends at its return level: the R plane (G99, absolute in G90) or the initial
        // level, the higher of the Z before and R (G98); its Z word is the hole's bottom.
        known_[a] = known_[a] || (absolute && state.retract == gcode::RetractMode::kRPlane);
      }
      else if (words.axes[a] && absolute)
      {
        known_[a] = true;
      }
    }
  }
  if (words.machine)
  {
    // G53/G28/G30 end in machine coordinates (the work offset is the control's): the axes they
    // move, every axis for a bare G28/G30 where the dialect moves them all.
    const bool bare_reference = words.reference && !words.anyAxis() && dialect_ != gcode::Dialect::kFanuc;
    if (bare_reference)
      forgetAll();
    else
      forget(words.axes);
  }
  if (words.block_delete)
    forget(words.axes);  // the operator's block-delete switch decides whether it ran
  if (block.call.kind != gcode::CallKind::kNone)
    forgetAll();
}

void CommandedPosition::refuse(const Words& words, const std::string& why)
{
  ++refused_;
  last_refusal_ = why;
  bool followed = true;
  for (const char* modal : words.modal)
  {
    try
    {
      parser_.parseLine(modal);
    }
    catch (const std::exception&)
    {
      followed = false;  // the parser's modes may now differ from the control's
    }
  }
  if (words.g92)
  {
    // The control re-zeroed the axes (every one for a bare G92), the parser did not.
    for (size_t a = 0; a < 3; ++a)
      shifted_[a] = shifted_[a] || words.axes[a] || !words.anyAxis();
  }
  if (!followed || words.unfollowable || words.call)
    forgetAll();
  else
    forget(words.axes);
}

void CommandedPosition::forget(const std::array<bool, 3>& axes)
{
  for (size_t a = 0; a < 3; ++a)
    known_[a] = known_[a] && !axes[a];
}

void CommandedPosition::forgetAll()
{
  known_ = {};
}

bool CommandedPosition::known() const
{
  for (size_t a = 0; a < 3; ++a)
  {
    if (!known_[a] || shifted_[a])
      return false;
  }
  return true;
}

gcode::Vec3 CommandedPosition::metres() const
{
  const gcode::Vec3& mm = parser_.position();
  return gcode::Vec3{mm.x / 1000.0, mm.y / 1000.0, mm.z / 1000.0};
}
}  // namespace dnc
}  // namespace cnc_bridge
