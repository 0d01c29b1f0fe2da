// A job for the ethernut board: a G-code program or a list of points, as the coordinates the board
// gets (docs/ethernut_node.md). A program is streamed in segments: the moves up to the program's
// next own step (stop, optional stop, dwell, spindle, coolant, tool change), which the node carries
// out between two segments, or up to its end (M02/M30; nothing after it is sent). Loading a job
// reads the whole program once: it counts the coordinates, builds the preview and refuses a bad
// program before anything is sent.
#pragma once

#include <atomic>
#include <cstdint>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/common/soft_limits.h"
#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
namespace ethernut
{
/// What to do with G53 moves (machine coordinates) in a G-code job. The board knows one
/// coordinate system, the one the program's coordinates are streamed in; a G53 target in it would
/// be a move to the wrong place (G53 Z0, a retract to the top of the machine, becomes a plunge to
/// the work zero).
enum class G53Moves : uint8_t
{
  kRefuse,  ///< the job is refused before anything is sent
  kSkip     ///< left out of the stream and the preview; the next move keeps the unnamed axes
};

/// The G53 policy and the name of the setting that chooses it (named when a job is refused).
struct G53Policy
{
  G53Moves moves = G53Moves::kRefuse;
  std::string setting = "g53_moves";
};

/// \brief How jobs are loaded (ethernut_node's ~program_dir, ~chord_tolerance, ~gcode_dialect,
/// ~tool_table, ~g53_moves, ~max_preview_points, ~soft_limits).
struct JobSettings
{
  std::string program_dir;  ///< G-code jobs are read from here only; "": point jobs only
  gcode::ParserOptions parser;
  G53Policy g53;
  size_t max_preview_points = 100000;
  SoftLimits soft_limits;  ///< every coordinate of a job is checked against them first (m, machine frame)
};

/// \brief The moves of a G-code program as the board gets them: G53 moves refused or left out.
/// Reads the program as it goes (one block at a time). Not thread-safe.
class GcodeJob
{
 public:
  /// \param in the program (e.g. an std::ifstream); kept by the job.
  GcodeJob(std::unique_ptr<std::istream> in, const gcode::ParserOptions& options, G53Policy g53);

  /// \brief The next move to stream; false at the end of the program, or at one of the program's
  /// own steps (stop, end, dwell, spindle, coolant, tool change), which step() then holds: the
  /// stream pauses there and the next call goes on after it.
  /// \throws ParseError, or ConfigError for a G53 move under G53Moves::kRefuse.
  bool next(gcode::Move& move);

  /// The program step next() stopped at, if it did not stop at the end of the program.
  const std::optional<gcode::ProgramStep>& step() const { return step_; }

  /// "" when no G53 move was left out, else e.g. "3 G53 moves left out (lines 8, 58, 63)"; at
  /// most five lines are named.
  std::string skippedSummary() const;

 private:
  std::unique_ptr<std::istream> in_;  // declared before steps_, which reads it
  gcode::ProgramSteps steps_;
  std::optional<gcode::ProgramStep> step_;
  G53Policy g53_;
  uint64_t skipped_ = 0;
  std::vector<uint32_t> skipped_lines_;
};

/// \brief The board's coordinate (mm, float) of a point given in mm, checked before any set of the
/// job is sent. Exact or refused: a value a float cannot carry (not finite, beyond its range, or
/// moved by more than 1 um by its rounding) or a point outside \p limits (metres) is refused.
/// \throws ConfigError naming \p where ("G-code line 12", "point 3"), the value and the limit.
Coordinate boardCoordinate(double x_mm, double y_mm, double z_mm, const SoftLimits& limits, const std::string& where);

/// \brief Opens a program file for GcodeJob. \throws ConfigError if it cannot be read.
std::unique_ptr<std::istream> openProgram(const std::string& path);

/// One pose of a job's preview, mm, with the kind of move that reaches it.
struct PreviewPoint
{
  double x = 0.0;
  double y = 0.0;
  double z = 0.0;
  bool rapid = false;  ///< reached by a rapid (G00) move, else by a feed move
};

/// \brief The preview of a job (the path it will take), in memory bounded by a number of points:
/// when the limit is reached it keeps every other point and from then on one in twice as many.
/// The first and the last point added are not always kept.
class Preview
{
 public:
  /// \param max_points at least 2 (smaller values are taken as 2).
  explicit Preview(size_t max_points);
  void add(double x_mm, double y_mm, double z_mm, bool rapid);
  /// The kept points in the order added; point i > 0 is reached from point i-1 by points()[i].rapid.
  const std::vector<PreviewPoint>& points() const { return points_; }
  /// Points added, kept or not.
  uint64_t added() const { return added_; }

 private:
  size_t max_points_;
  uint64_t stride_ = 1;
  uint64_t added_ = 0;
  std::vector<PreviewPoint> points_;
};

/// \brief One job, loaded and ready to stream: its coordinates (the program's moves or the given
/// points), their count and its preview. Thread-safe where said: the client's thread takes the
/// coordinates (next()) while the node's thread reads the rest.
class Job
{
 public:
  /// \brief Loads a G-code program: counts its moves up to its end and builds the preview (the
  /// start of the first move, then the end of every move).
  /// Every move's end is checked (boardCoordinate()) before the job exists, so a program with one
  /// coordinate the board cannot take is refused whole, with nothing sent.
  /// \throws ConfigError (an unreadable file, a G53 move to refuse, a coordinate a float cannot
  /// carry or outside \p limits), ParseError.
  static std::unique_ptr<Job> fromProgram(const std::string& path, const gcode::ParserOptions& options,
                                          const G53Policy& g53, size_t max_preview_points,
                                          const SoftLimits& limits = SoftLimits());
  /// \brief A job of points (mm, machine frame), streamed in one segment.
  static std::unique_ptr<Job> fromPoints(std::vector<Coordinate> points, size_t max_preview_points);

  uint64_t coordinateCount() const { return count_; }
  const Preview& preview() const { return preview_; }
  /// G53 moves left out (GcodeJob::skippedSummary()), "" for none.
  const std::string& skippedSummary() const { return skipped_; }

  /// \brief The next coordinate of the current segment (its tag: the G-code line, 0 for points);
  /// false at the segment's end. The source Client::startJob takes. \throws as GcodeJob::next().
  bool next(Coordinate& out);
  /// \brief The program step the last segment ended at: nothing at the program's end (or for
  /// points), the step (M02/M30 included) otherwise. Call it once the segment has ended.
  std::optional<gcode::ProgramStep> stepAtEnd() const;
  /// \brief True once the current segment ended at a step after which the job goes on (not at
  /// M02/M30, not at the program's end). Any thread.
  bool segmentContinues() const { return segment_continues_; }
  /// \brief Clears segmentContinues() before the next segment is started.
  void startSegment() { segment_continues_ = false; }

 private:
  explicit Job(size_t max_preview_points) : preview_(max_preview_points) {}

  uint64_t count_ = 0;
  Preview preview_;
  std::string skipped_;
  std::unique_ptr<GcodeJob> program_;  // a program job
  std::vector<Coordinate> points_;     // a points job
  size_t next_point_ = 0;
  std::atomic<bool> segment_continues_{false};
};
}  // namespace ethernut
}  // namespace cnc_bridge
