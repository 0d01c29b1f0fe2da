// G-code program to '@' path (see program_path.h).
#include "cnc_bridge/at_protocol/program_path.h"

#include <cmath>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
void appendProgram(std::istream& in, const gcode::ParserOptions& options, double goal_feed, double fallback_feed,
                   PathPlan& plan)
{
  gcode::forEachMove(
      in,
      [&](const gcode::Move& move)
      {
        plan.points.push_back({move.end.x * kPulsesPerMm, move.end.y * kPulsesPerMm, move.end.z * kPulsesPerMm});
        double feed = goal_feed > 0.0 ? goal_feed : fallback_feed;
        if (move.motion == gcode::Motion::kRapid)
        {
          feed = 1e9;  // as fast as the axes allow
        }
        else if (goal_feed <= 0.0 && move.feed_mm_per_min > 0.0)
        {
          feed = move.feed_mm_per_min / 60.0;
        }
        plan.feeds.push_back(feed);
        plan.coolant = plan.coolant || move.coolant;
        if (move.spindle == gcode::Spindle::kClockwise)
        {
          plan.spindle_rpm = move.spindle_rpm;
        }
      },
      options);
}

void roundToPulses(PathPlan& plan)
{
  for (auto& point : plan.points)
  {
    for (double& c : point)
    {
      if (!(std::fabs(c) < 2.0e9))
      {
        throw ConfigError("a path point is outside the protocol's range (+-2147 m)");
      }
      c = std::round(c);  // whole pulses: the end point is exact
    }
  }
}
}  // namespace at_protocol
}  // namespace cnc_bridge
