// The path the '@' controller follows for a G-code program or a point list, as operations in
// pulses with a feed per segment: one planning function for at_controller_node's follow_path and
// for the cnc_plan tool, so the tool's dry run plans exactly what the node sends.
#pragma once

#include <cstdint>
#include <istream>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/common/soft_limits.h"
#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief One operation (M1@ ... #@): the controller's unit of motion, a stretch of moves from
/// rest to rest. Coolant, spindle and tool are set before its setpoints (P@, T@, S@: the protocol
/// sets them only at an operation's start), and the program's own step that follows it (stop,
/// optional stop, dwell, end) is carried out between this operation and the next.
struct OperationPlan
{
  std::vector<Vec3> points;   ///< pulses, from where the previous operation ends
  std::vector<double> feeds;  ///< mm/s per segment
  bool coolant = false;
  double spindle_rpm = 0.0;                 ///< 0: spindle off
  int32_t tool = -1;                        ///< tool change before the moves (T@), -1: none
  bool cuts = false;                        ///< has a feed move (not only positioning rapids)
  std::optional<gcode::ProgramStep> after;  ///< stop, optional stop, dwell or end after the moves

  /// \brief False for an operation without moves (a spindle or coolant change after the last cut,
  /// a stop right after another): nothing is sent for it, only its step after is carried out.
  bool moves() const { return points.size() > 1; }
};

struct ProgramPlanOptions
{
  double goal_feed = 0.0;      ///< mm/s for every feed move if positive, else the program's F
  double fallback_feed = 0.0;  ///< mm/s for feed moves when neither the goal nor the program gives one
  bool coolant = false;        ///< coolant at the start, until the program switches it
  /// Whether the program's spindle, coolant and tool words become the controller's commands; if
  /// not, a program with one is refused naming its line and \c program_commands_setting.
  bool program_commands = false;
  std::string program_commands_setting = "program_commands";
  /// rev/min of the spindle's top speed: an S word above it is refused naming its line (0: unchecked).
  double spindle_max_rpm = 0.0;
  /// Every move's end must lie inside these (metres, machine frame); refused naming the line.
  SoftLimits soft_limits;
};

/// \brief Plans the program in \p in from \p start (pulses) as operations: one for a program
/// without its own steps; a new one after each M00, M01, G04 and, when the program's commands are
/// taken, after each change of spindle, coolant or tool that follows a cut (before the first cut,
/// after positioning rapids only, the change applies to the operation under way). Nothing after
/// M02/M30 is planned. Program millimetres are machine millimetres, 1000 pulses each; rapids at
/// the axes' limits, feed moves at ProgramPlanOptions::goal_feed, the program's F or
/// ProgramPlanOptions::fallback_feed.
/// \throws ConfigError for a program the controller cannot carry out (a refused machine command,
/// M04), gcode::ParseError and Error as gcode::Reader.
std::vector<OperationPlan> planProgram(std::istream& in, const gcode::ParserOptions& options,
                                       const ProgramPlanOptions& plan_options, const Vec3& start);

/// \brief Rounds every point to whole pulses (so the end point is exact).
/// \throws ConfigError if a point is outside the protocol's range (+-2147 m).
void roundToPulses(OperationPlan& plan);
}  // namespace at_protocol
}  // namespace cnc_bridge
