// G-code program to '@' operations (see program_path.h).
#include "cnc_bridge/at_protocol/program_path.h"

#include <cmath>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
using Kind = gcode::ProgramStep::Kind;

/// Collects the operations of one program: the moves of the one under way, the modal values the
/// next one starts with.
class OperationPlanner
{
 public:
  OperationPlanner(const ProgramPlanOptions& options, const Vec3& start) : options_(options), coolant_(options.coolant)
  {
    plans_.emplace_back();
    plans_.back().points.push_back(start);
    plans_.back().coolant = coolant_;
  }

  /// \returns false after the program's end.
  bool add(const gcode::ProgramStep& step)
  {
    if (step.isMachineCommand() && !options_.program_commands)
    {
      throw ConfigError("program refused: line " + std::to_string(step.line) + ": " + step.describe() +
                        " commands the machine; set " + options_.program_commands_setting +
                        " true to send the program's spindle, coolant and tool commands to the controller "
                        "(S@, P1@/P0@, T@), or take them out of the program");
    }
    switch (step.kind)
    {
      case Kind::kMove:
        addMove(step.move);
        return true;
      case Kind::kSpindle:
        if (step.spindle == gcode::Spindle::kCounterClockwise)
        {
          throw ConfigError("program refused: line " + std::to_string(step.line) + ": " + step.describe() +
                            ": the controller turns the spindle clockwise only");
        }
        spindle_rpm_ = step.spindle == gcode::Spindle::kClockwise ? step.spindle_rpm : 0.0;
        if (options_.spindle_max_rpm > 0.0 && !(spindle_rpm_ <= options_.spindle_max_rpm))
        {
          throw ConfigError("program refused: line " + std::to_string(step.line) + ": " + step.describe() +
                            ": spindle speed above ~spindle_max_rpm (" + std::to_string(options_.spindle_max_rpm) +
                            " rev/min)");
        }
        break;
      case Kind::kCoolant:
        coolant_ = step.coolant;
        break;
      case Kind::kToolChange:
        tool_ = step.tool;
        break;
      default:  // stop, optional stop, dwell, end: the operation ends here
        nextOperation(step);
        if (step.kind == Kind::kEnd)
        {
          plans_.pop_back();
          return false;
        }
        return true;
    }
    applyMachineCommand(step.kind == Kind::kToolChange);
    return true;
  }

  std::vector<OperationPlan> take() { return std::move(plans_); }

 private:
  // The whole program is checked while it is planned, before anything is sent: every move's end
  // in the protocol's range (int32 pulses) and inside the soft limits.
  void checkMove(const gcode::Move& move) const
  {
    const std::string where = "program refused: line " + std::to_string(move.line) + ": ";
    for (const double mm : {move.end.x, move.end.y, move.end.z})
    {
      if (!(std::fabs(mm * kPulsesPerMm) < 2147483647.0))
      {
        throw ConfigError(where + "a coordinate " + std::to_string(mm) +
                          " mm is outside the protocol's range (+-2147 m in whole pulses)");
      }
    }
    const std::string outside =
        options_.soft_limits.violation({move.end.x / 1000.0, move.end.y / 1000.0, move.end.z / 1000.0});
    if (!outside.empty())
    {
      throw ConfigError(where + outside);
    }
  }

  void addMove(const gcode::Move& move)
  {
    checkMove(move);
    OperationPlan& plan = plans_.back();
    plan.points.push_back({move.end.x * kPulsesPerMm, move.end.y * kPulsesPerMm, move.end.z * kPulsesPerMm});
    double feed = options_.goal_feed > 0.0 ? options_.goal_feed : options_.fallback_feed;
    if (move.motion == gcode::Motion::kRapid)
    {
      feed = 1e9;  // as fast as the axes allow
    }
    else if (options_.goal_feed <= 0.0 && move.feed_mm_per_min > 0.0)
    {
      feed = move.feed_mm_per_min / 60.0;
    }
    plan.feeds.push_back(feed);
    plan.cuts = plan.cuts || move.motion != gcode::Motion::kRapid;
  }

  // A new spindle, coolant or tool value: the next moves are a new operation with it (the protocol
  // sets them only at an operation's start). Before the operation's first cut (after positioning
  // rapids only) it applies to that operation.
  void applyMachineCommand(bool tool_change)
  {
    if (plans_.back().cuts)
    {
      nextOperation(std::nullopt);
    }
    OperationPlan& plan = plans_.back();
    plan.coolant = coolant_;
    plan.spindle_rpm = spindle_rpm_;
    if (tool_change)
    {
      plan.tool = tool_;
    }
  }

  // Starts a new operation where the last one ends, with the modal values now in force.
  void nextOperation(std::optional<gcode::ProgramStep> after)
  {
    plans_.back().after = after;
    OperationPlan fresh;
    fresh.points.push_back(plans_.back().points.back());
    fresh.coolant = coolant_;
    fresh.spindle_rpm = spindle_rpm_;
    plans_.push_back(std::move(fresh));
  }

  const ProgramPlanOptions& options_;
  std::vector<OperationPlan> plans_;
  bool coolant_;
  double spindle_rpm_ = 0.0;
  int32_t tool_ = -1;
};
}  // namespace

std::vector<OperationPlan> planProgram(std::istream& in, const gcode::ParserOptions& options,
                                       const ProgramPlanOptions& plan_options, const Vec3& start)
{
  gcode::ProgramSteps steps(in, options);
  OperationPlanner planner(plan_options, start);
  gcode::ProgramStep step;
  while (steps.next(step) && planner.add(step))
  {
  }
  return planner.take();
}

void roundToPulses(OperationPlan& plan)
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
