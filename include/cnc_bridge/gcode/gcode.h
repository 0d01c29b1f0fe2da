// A streaming G-code parser for the subset real CAM output and qCNC's converter use: it turns lines
// of a part program into plain blocks and straight-line moves (arcs already cut into chords) in
// millimetres, so that a job preview, a coordinate streamer (ethernut) and a path planner
// (at_controller) all read programs the same way. Memory stays constant whatever the file size:
// one line is parsed at a time and its moves reuse the same buffer.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <istream>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace gcode
{
/// A point or vector in program coordinates, millimetres.
struct Vec3
{
  double x = 0.0;
  double y = 0.0;
  double z = 0.0;
};

/// Modal motion group (group 1).
enum class Motion : uint8_t
{
  kNone,    ///< G80: no motion mode; axis words alone are an error
  kRapid,   ///< G00
  kLinear,  ///< G01
  kArcCw,   ///< G02
  kArcCcw   ///< G03
};

/// Arc plane (group 2). Axes (u, v, normal): G17 (X, Y, Z), G18 (Z, X, Y), G19 (Y, Z, X), so that
/// G02 is clockwise looking from the positive end of the normal axis towards the origin in each.
enum class Plane : uint8_t
{
  kXY,  ///< G17
  kZX,  ///< G18
  kYZ   ///< G19
};

enum class Units : uint8_t
{
  kMillimetres,  ///< G21
  kInches        ///< G20: every length and feed word is multiplied by 25.4
};

enum class DistanceMode : uint8_t
{
  kAbsolute,    ///< G90
  kIncremental  ///< G91 (axis words only; I/J/K are always relative to the arc start)
};

enum class Spindle : uint8_t
{
  kOff,              ///< M05
  kClockwise,        ///< M03
  kCounterClockwise  ///< M04
};

const char* toString(Motion motion);
const char* toString(Plane plane);

/// The modal state after a block.
struct ModalState
{
  Motion motion = Motion::kLinear;
  Plane plane = Plane::kXY;
  Units units = Units::kMillimetres;
  DistanceMode distance = DistanceMode::kAbsolute;
  double feed_mm_per_min = 0.0;  ///< 0 until an F word is seen (inch/min under G20 converted)
  double spindle_rpm = 0.0;      ///< last S word
  Spindle spindle = Spindle::kOff;
  int32_t selected_tool = -1;  ///< last T word (-1: none)
  int32_t tool = -1;           ///< tool in the spindle: the selected tool after M06 (-1: unknown)
  bool coolant = false;        ///< M07/M08 on, M09 off
};

/// \brief One straight move of the tool: a G00/G01 block, or one chord of a G02/G03 arc.
struct Move
{
  Motion motion = Motion::kLinear;  ///< kRapid, kLinear, or kArcCw/kArcCcw for an arc chord
  Vec3 start;                       ///< mm, absolute program coordinates
  Vec3 end;                         ///< mm, absolute program coordinates
  double feed_mm_per_min = 0.0;     ///< modal feed (also carried on rapids; 0 = never programmed)
  double spindle_rpm = 0.0;
  Spindle spindle = Spindle::kOff;
  int32_t tool = -1;
  bool coolant = false;
  /// G53 block: the coordinates are machine coordinates. Work offsets (G54..G59, G43) are not
  /// known to the parser, so such moves are in a different frame; previews may skip them.
  bool machine_coordinates = false;
  uint32_t line = 0;           ///< 1-based source line
  int64_t block_number = -1;   ///< N word, -1 if the block had none
  uint32_t segment = 0;        ///< index of this chord within its arc (0 for straight moves)
  uint32_t segment_count = 1;  ///< chords the arc was cut into (1 for straight moves)
};

/// \brief Everything one source line said, after it was applied to the modal state.
struct Block
{
  static constexpr size_t kMaxMCodes = 4;

  uint32_t line = 0;                           ///< 1-based source line
  int64_t block_number = -1;                   ///< N word, -1 if none
  int64_t program_number = -1;                 ///< O word, -1 if none
  bool tape_marker = false;                    ///< the line was a '%' (start/end of tape)
  bool deleted = false;                        ///< '/' block skipped under ParserOptions::block_delete
  bool has_words = false;                      ///< false for blank and comment-only lines
  std::array<uint16_t, kMaxMCodes> m_codes{};  ///< M words in source order (M03, M06, M30, ...)
  uint8_t m_count = 0;
  bool tool_change = false;   ///< M06
  bool program_stop = false;  ///< M00 or M01
  bool program_end = false;   ///< M02 or M30
  double dwell_s = -1.0;      ///< G04 P seconds, -1 if no dwell
  std::vector<Move> moves;    ///< 0 moves, 1 straight move, or the chords of one arc
};

/// \brief Bad input: says where (1-based line and column) and what.
class ParseError : public ProtocolError
{
 public:
  ParseError(uint32_t line, uint32_t column, const std::string& reason);
  uint32_t line() const { return line_; }
  uint32_t column() const { return column_; }
  const std::string& reason() const { return reason_; }

 private:
  uint32_t line_;
  uint32_t column_;
  std::string reason_;
};

struct ParserOptions
{
  /// Largest distance (mm) between an arc and the chords that replace it (the sagitta).
  double chord_tolerance_mm = 0.01;
  /// An arc whose start and end radii differ by more than this (mm) or 0.1 % is an error.
  double arc_radius_tolerance_mm = 0.0127;
  /// More chords than this for one arc: the chord count is capped (the tolerance is then coarser).
  uint32_t max_arc_segments = 10000;
  /// Lines longer than this (bytes, without the newline) are an error, so one line cannot take
  /// unbounded memory.
  size_t max_line_length = 4096;
  /// Skip blocks starting with '/' (the control's block-delete switch).
  bool block_delete = false;
  Units initial_units = Units::kMillimetres;
  /// qCNC's converter never writes G01/G90 ("default is G90 and G01", ethernut.md#g-code-phrasing), so a program
  /// that moves before any motion word is read as feed moves: the slower, safer reading.
  Motion initial_motion = Motion::kLinear;
  Vec3 initial_position;  ///< mm
  /// For consumers that keep G53 (machine coordinate) moves apart from the program, e.g. a
  /// streamer to a board that knows one coordinate system and refuses or skips them: a G53 block
  /// always yields its move (flagged Move::machine_coordinates), even when its numbers equal the
  /// program position, and leaves position() unchanged, so the next move starts where the last
  /// program move ended and keeps that move's values on the axes it does not name. Off: a G53
  /// target becomes the program position (the numbers of two frames mixed, as a preview that
  /// draws everything in one frame does).
  bool separate_machine_moves = false;
};

/// \brief Parses one line at a time, keeping the modal state between lines.
///
/// Language: comments `( ... )` and `; ...`; `%` tape markers; O program numbers; N block numbers;
/// '/' block delete; G00 G01 G02 G03 G04 G17 G18 G19 G20 G21 G80 G90 G91; G53 (this block in
/// machine coordinates); G40 G43 G49 G54-G59 G94 accepted without effect on the geometry (their
/// offsets live in the control); F S T H D P words; M00 M01 M02 M03 M04 M05 M06 M07 M08 M09 M30
/// act on the modal state, every M code is reported in Block::m_codes; X Y Z I J K R. Arcs: I/J/K
/// centre offsets (always incremental from the start point) or R (negative R: the arc longer than a
/// half circle), helical when the normal axis moves; a full circle when the IJK end equals the
/// start. Letters are
/// case-insensitive; spaces between words and between a letter and its number are allowed.
/// Unsupported features (macros `#`/`[`, rotary axes, canned cycles, unknown G codes) are errors,
/// never silently ignored, because a planner downstream would move the wrong way.
///
/// Not thread-safe; one parser per program.
class Parser
{
 public:
  explicit Parser(const ParserOptions& options = ParserOptions());

  /// \brief Parses the next line of the program (without its newline; a trailing CR is ignored).
  /// \returns the block, valid until the next call. Its line is the count of calls so far.
  /// \throws ParseError with line and column; the modal state and position are left as they were
  ///         before the line.
  const Block& parseLine(std::string_view text);

  /// \brief Current modal state.
  const ModalState& state() const { return state_; }
  /// \brief Current tool position, mm, absolute program coordinates.
  const Vec3& position() const { return position_; }
  /// \brief Lines parsed so far.
  uint32_t lineCount() const { return line_; }
  const ParserOptions& options() const { return options_; }
  /// \brief Back to the initial state, for parsing another program.
  void reset();

 private:
  ParserOptions options_;
  ModalState state_;
  Vec3 position_;
  uint32_t line_ = 0;
  Block block_;
};

/// \brief Reads a program from a stream in fixed-size chunks and parses it line by line.
///
/// Memory is bounded by the chunk size, ParserOptions::max_line_length and the chords of one arc.
/// Not thread-safe.
class Reader
{
 public:
  /// \param in the program; must outlive the reader.
  explicit Reader(std::istream& in, const ParserOptions& options = ParserOptions());

  /// \brief Parses the next line.
  /// \returns the block, valid until the next call; nullptr at the end of the stream.
  /// \throws ParseError (also for a line longer than max_line_length), Error if the stream fails.
  const Block* nextBlock();

  /// \brief The next move of the program, across blocks (blocks without moves are skipped).
  /// \returns false at the end of the stream.
  /// \throws as nextBlock().
  bool nextMove(Move& move);

  const Parser& parser() const { return parser_; }

 private:
  bool nextLine(std::string_view& line);

  std::istream& in_;
  Parser parser_;
  std::vector<char> buffer_;
  size_t begin_ = 0;
  size_t end_ = 0;
  bool eof_ = false;
  const Block* block_ = nullptr;
  size_t move_index_ = 0;
};

/// \brief Calls \p on_move for every move of the program in \p in, in order.
/// \throws ParseError, Error as Reader.
template <typename OnMove>
void forEachMove(std::istream& in, OnMove&& on_move, const ParserOptions& options = ParserOptions())
{
  Reader reader(in, options);
  while (const Block* block = reader.nextBlock())
  {
    for (const Move& move : block->moves)
    {
      on_move(move);
    }
  }
}

/// \brief Axis-aligned bounds of a set of moves (mm), for previews and checks.
struct Bounds
{
  Vec3 min{1e300, 1e300, 1e300};
  Vec3 max{-1e300, -1e300, -1e300};
  bool empty() const { return min.x > max.x; }
  void add(const Vec3& p);
};

}  // namespace gcode
}  // namespace cnc_bridge
