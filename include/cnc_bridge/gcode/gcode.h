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
#include <optional>
#include <string>
#include <string_view>
#include <utility>
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

/// \brief Where the controls differ (G04 P units, M97, the Fanuc subprogram P form, G76, what a
/// bare G28 does, the peck clearance of G73/G83), the parser follows one of them.
enum class Dialect : uint8_t
{
  kHaas,     ///< Haas mills (the default): G04 P with a decimal point in seconds, without in ms; M97
  kFanuc,    ///< Fanuc 0i/30i-style: G04 P in ms (G04 X in s); K repeats; M98 P<4 digits L><4 digits O>
  kLinuxCnc  ///< LinuxCNC (rs274ngc): G04 P in seconds; G76 is a lathe threading cycle (refused)
};

/// G98/G99: where a canned cycle returns between holes.
enum class RetractMode : uint8_t
{
  kInitialLevel,  ///< G98: to the Z of the block that started the cycles (or R, if that is higher)
  kRPlane         ///< G99: to the R plane
};

/// G40/G41/G42.
enum class CutterComp : uint8_t
{
  kOff,   ///< G40
  kLeft,  ///< G41: the tool to the left of the programmed path, seen along the direction of travel
  kRight  ///< G42
};

/// G61/G64/G187/G103: how the program asks corners to be taken. Hints for a planner; the geometry
/// is the same in every mode.
enum class PathMode : uint8_t
{
  kUnspecified,  ///< nothing programmed
  kExactStop,    ///< G61: stop at every corner
  kBlend         ///< G64: blend corners (LinuxCNC G64 P: tolerance), G187 (Haas smoothing)
};

/// What a canned cycle needs the spindle to do when the tool reaches the end of a move.
enum class SpindleAction : uint8_t
{
  kNone,
  kStop,       ///< G86: stop the spindle before the rapid out of the hole
  kReverse,    ///< G84/G74 at the bottom: reverse the spindle to feed out of the thread
  kResume,     ///< back to the direction (or rotation) the program had before the cycle
  kOrientStop  ///< G76 at the bottom: oriented spindle stop before the shift away from the wall
};

const char* toString(Motion motion);
const char* toString(Plane plane);
const char* toString(Dialect dialect);
/// \brief "haas", "fanuc" or "linuxcnc" (case-insensitive). \throws ConfigError for anything else.
Dialect parseDialect(const std::string& name);

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

  RetractMode retract = RetractMode::kInitialLevel;  ///< G98/G99
  /// Active canned cycle: 73, 74, 76, 81..86 or 89 (its G number), 0 when none (G80 or another
  /// motion mode). While a cycle is active, motion is Motion::kNone and every block with X/Y/Z
  /// words drills again.
  uint16_t canned_cycle = 0;
  /// The cycle's modal numbers (mm, seconds), kept from block to block as the controls keep them.
  struct Cycle
  {
    double r_word = 0.0;     ///< R as written (mm): read per block in G90 or G91
    double z_word = 0.0;     ///< Z as written (mm)
    double r = 0.0;          ///< R plane of the last cycle block, Z in the program's starting frame
    double bottom = 0.0;     ///< Z of the hole's bottom, same frame
    double peck = 0.0;       ///< Q: peck depth (G73/G83) or shift (G76)
    double dwell_s = 0.0;    ///< P at the bottom
    double initial_z = 0.0;  ///< Z before the first cycle block (G98 return level)
    bool have_r = false;
    bool have_bottom = false;
    bool have_dwell = false;
  } cycle;

  /// G92 shift (mm): a number the program writes for an axis means number + offset in the frame
  /// the program started in. G92.1 clears it, G92.2 suspends it, G92.3 restores what G92.2 kept.
  Vec3 g92_offset;
  Vec3 g92_saved;

  CutterComp cutter_comp = CutterComp::kOff;
  double comp_radius_mm = 0.0;  ///< radius from the tool table while G41/G42 is on

  PathMode path_mode = PathMode::kUnspecified;
  double path_tolerance_mm = 0.0;  ///< G64 P (LinuxCNC), G187 E (Haas); 0: the control's default
  /// G64 Q (LinuxCNC naive CAM detector: collinear moves within it are merged); 0: not programmed
  double naive_cam_tolerance_mm = 0.0;
  int32_t smoothing_level = 0;    ///< G187 P1..P3 (Haas rough/medium/finish), 0: default
  int32_t lookahead_blocks = -1;  ///< G103 P (Haas; 0: the control's maximum), -1: not programmed
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

  /// Canned cycle this move was expanded from (its G number: 73, 81, 83, ...), 0 otherwise.
  uint16_t cycle = 0;
  /// Dwell at this move's end point, seconds (a cycle's P at the bottom of the hole).
  double dwell_after_s = 0.0;
  /// Spindle action the cycle needs once the tool is at this move's end point (tapping, boring).
  SpindleAction spindle_after = SpindleAction::kNone;
  /// G28/G30: the move to the reference point, in machine coordinates (machine_coordinates is set
  /// too, so a consumer's G53 policy applies to it).
  bool reference_return = false;
  /// Offset by G41/G42 cutter compensation (the tool centre's path, not the programmed contour).
  bool compensated = false;
};

/// M98 (subprogram by O number), M97 (Haas: local subprogram by N number within the file).
enum class CallKind : uint8_t
{
  kNone,
  kSubprogram,  ///< M98 P<O number>
  kLocal        ///< M97 P<N number>
};

struct SubprogramCall
{
  CallKind kind = CallKind::kNone;
  int64_t label = -1;    ///< the O (M98) or N (M97) number called
  uint32_t repeats = 1;  ///< L (or the Fanuc P prefix): how many times the subprogram runs
  uint32_t column = 0;   ///< column of the M word, for errors
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
  double dwell_s = -1.0;      ///< G04 dwell in seconds (P per the dialect), -1 if no dwell
  std::vector<Move> moves;    ///< 0 moves, 1 straight move, the chords of one arc, or a cycle's moves
  /// M98/M97 in this block: Reader jumps there after the block's own moves.
  SubprogramCall call;
  bool subprogram_end = false;  ///< M99: back to the caller (Reader); in a main program it ends it
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

  /// Where the controls differ; see Dialect.
  Dialect dialect = Dialect::kHaas;
  /// Subprograms (M98/M97) nested deeper than this are an error (a subprogram calling itself).
  uint32_t max_call_depth = 8;
  /// More blocks than this read inside subprograms (repeats of repeats) is an error, so that a
  /// program cannot make a reader run for ever.
  uint64_t max_subprogram_blocks = 10000000;
  /// Machine coordinates (mm) of the G28 and G30 reference points (the Haas/Fanuc machine zero,
  /// LinuxCNC's parameters 5161-5163 and 5181-5183 are 0 on a fresh control).
  Vec3 g28_position;
  Vec3 g30_position;
  /// G73 retract and G83 clearance above the last peck (mm); negative: the dialect's (LinuxCNC
  /// 0.010 in, Haas setting 22 default 0.050 in, Fanuc parameter 5114/5115 taken as 0.050 in).
  double peck_clearance_mm = -1.0;
  /// More moves than this out of one canned-cycle block (pecks x repeats) is an error.
  uint32_t max_cycle_moves = 100000;
  /// Tool radii for G41/G42 (D word: the tool number; LinuxCNC without D: the tool in the
  /// spindle). Without a table a program with G41/G42 is refused.
  std::shared_ptr<const class ToolTable> tool_table;
};

/// \brief Tool radii by tool number, for cutter compensation.
class ToolTable
{
 public:
  /// \brief Reads a LinuxCNC tool table (`T1 P1 D6.0 Z... ;comment`, D the diameter in the
  /// table's units, taken as \p units) or, for a name ending in .yaml/.yml, a YAML map
  /// `tools: {1: {diameter: 6.0}, 2: {radius: 2.5}}` (mm).
  /// \throws ConfigError naming the file, line and what is wrong.
  static ToolTable load(const std::string& path, Units units = Units::kMillimetres);
  static ToolTable parseLinuxCnc(std::istream& in, const std::string& name, Units units = Units::kMillimetres);
  static ToolTable parseYaml(const std::string& text, const std::string& name);

  void setRadius(int32_t tool, double radius_mm);
  /// \returns the radius in mm, or a negative number if the tool is not in the table.
  double radius(int32_t tool) const;
  size_t size() const { return radius_mm_.size(); }

 private:
  std::vector<std::pair<int32_t, double>> radius_mm_;  // sorted by tool number
};

/// \brief Parses one line at a time, keeping the modal state between lines.
///
/// Language (docs/gcode.md has the table): comments, `%`, O and N numbers, '/' block delete;
/// G00-G03 (arcs by IJK or R, helical), G04, G17-G19, G20/G21, G28/G30, G40-G42 (cutter
/// compensation with a tool table), G53, G61/G64/G187/G103 (hints), G73/G74/G76/G81-G86/G89 canned
/// cycles with G98/G99 and L/K repeats, G80, G90/G91, G92/G92.1-G92.3; G43 G49 G54-G59 G94 and the
/// usual cancel codes without effect on the geometry; M00-M09, M30, M97/M98/M99 (reported in the
/// block; Reader follows them); X Y Z I J K R F S T H D P Q L E. Where the controls differ
/// ParserOptions::dialect decides. Unsupported features (macros, rotary axes, unknown G codes) are
/// errors, never silently ignored, because a planner downstream would move the wrong way.
///
/// Not thread-safe; one parser per program.
struct Arc;  // an arc's geometry (internal)

class Parser
{
 public:
  explicit Parser(ParserOptions options = ParserOptions());

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
  /// \brief The next line parsed is line \p line (Reader, after a jump to a subprogram).
  void setNextLine(uint32_t line) { line_ = line - 1; }
  /// \brief Moves held back by cutter compensation (the last compensated move waits for the next
  /// one to know its corner); flushed as the program ends. \returns false if there is nothing.
  /// \throws ParseError if compensation is still on (a program must end with G40).
  bool finish(Block& out);

  // Defined in src/core/gcode (the words of a line, one block's working state, cutter compensation).
  struct Scan;
  struct Step;
  struct Comp;

 private:
  // Applying a block's words (gcode_words.cpp).
  void applyWords(const Scan& scan, Step& step);
  void applyDwell(const Scan& scan, Step& step) const;
  void applyMotion(const Scan& scan, Step& step);
  void moveToAxisWords(const Scan& scan, Step& step);
  void finishBlock(const Scan& scan, Step& step);
  static Move proto(const Step& step, Motion motion);
  static void emitRaw(Step& step, const Move& move);
  void moveStraight(const Scan& scan, Step& step, const Vec3& target);
  void moveArc(const Scan& scan, Step& step, const Vec3& target);
  Arc arcGeometry(const Scan& scan, const Step& step, const Vec3& start, const Vec3& target) const;
  void emitArc(Step& step, const Move& proto, const Arc& arc) const;
  void runCycle(const Scan& scan, Step& step);
  void referenceReturn(const Scan& scan, Step& step, bool g30);
  double dwellSeconds(const Scan& scan, int word) const;
  // Cutter compensation (gcode_comp.cpp).
  void compensatedStraight(Step& step, const Move& move);
  /// G40 with a straight move: the exit from the offset path to the programmed point.
  void compensationExit(Step& step, const Move& move);
  void compensatedArc(Step& step, const Move& move, const Arc& arc);
  static void compensationOn(Step& step);
  void compensationOff(Step& step, bool program_end);
  void emitHeld(Step& step, Comp& comp);
  void joinHeld(Step& step, Comp& comp, bool next_arc, double ncu, double ncv, double nrad, bool ncw, Vec3& next_start,
                double ntx, double nty, const Vec3& corner);

  ParserOptions options_;
  ModalState state_;
  Vec3 position_;
  uint32_t line_ = 0;
  Block block_;
  // Cutter compensation: the last offset move, not emitted until the next move decides its end.
  std::shared_ptr<Comp> comp_;
  std::shared_ptr<Comp> comp_scratch_;  // the working copy of one line
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
  /// Subprograms entered and not yet left (M98/M97 without their M99).
  size_t callDepth() const { return calls_.size(); }

 private:
  struct Label
  {
    uint64_t offset = 0;  // byte offset of the label's line in the stream
    uint32_t line = 0;    // its 1-based line number
  };
  struct Frame
  {
    Label target;
    uint64_t return_offset = 0;
    uint32_t return_line = 0;
    uint32_t remaining = 0;  // runs of the subprogram still to come after this one
  };
  bool nextLine(std::string_view& line);
  void call(const Block& block);
  void jump(const Label& label);
  Label findLabel(char letter, int64_t number, const Block& caller);

  std::istream& in_;
  Parser parser_;
  std::vector<char> buffer_;
  size_t begin_ = 0;
  size_t end_ = 0;
  bool eof_ = false;
  const Block* block_ = nullptr;
  size_t move_index_ = 0;
  // Stream offset of buffer_[0]; -1 as start when the stream cannot tell (then no subprograms).
  int64_t stream_start_ = -1;
  uint64_t base_ = 0;
  uint64_t line_offset_ = 0;  // offset of the line nextLine() returned last
  std::vector<Frame> calls_;
  std::vector<std::pair<int64_t, Label>> o_labels_;  // O numbers seen (M98 targets)
  std::vector<std::pair<int64_t, Label>> n_labels_;  // N numbers asked for by M97
  uint64_t subprogram_blocks_ = 0;                   // blocks read inside subprograms
  bool ended_ = false;                               // M02/M30, or M99 in the main program
  bool flushed_ = false;
  Block tail_;  // moves flushed by Parser::finish() at the end
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
