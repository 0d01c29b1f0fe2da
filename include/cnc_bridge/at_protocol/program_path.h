// The path the '@' controller follows for a G-code program or a point list, in pulses with a feed
// per segment: one function for at_controller_node's follow_path and for the cnc_plan tool, so the
// tool's dry run plans exactly what the node would send.
#pragma once

#include <istream>
#include <vector>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace at_protocol
{
struct PathPlan
{
  std::vector<Vec3> points;   ///< pulses, the start first
  std::vector<double> feeds;  ///< mm/s per segment
  bool coolant = false;       ///< the program switched coolant on
  double spindle_rpm = 0.0;   ///< last S with M03
};

/// \brief Appends the moves of the program in \p in to \p plan (which holds the start point):
/// program millimetres are machine millimetres, 1000 pulses each; rapids at the axes' limits,
/// feed moves at \p goal_feed (mm/s) if positive, else the program's F, else \p fallback_feed.
/// \throws gcode::ParseError, Error as gcode::Reader.
void appendProgram(std::istream& in, const gcode::ParserOptions& options, double goal_feed, double fallback_feed,
                   PathPlan& plan);

/// \brief Rounds every point to whole pulses (so the end point is exact).
/// \throws ConfigError if a point is outside the protocol's range (+-2147 m).
void roundToPulses(PathPlan& plan);
}  // namespace at_protocol
}  // namespace cnc_bridge
