// Time to cycle end (docs/cell_monitor.md): a part program planned with the project's G-code parser
// (ProgramSteps) and the '@' path planner (at_protocol::Trajectory, trapezoid, with its look-ahead
// through corners) under a machine's cycle profile, as the planned time of each block; and a
// countdown that follows a running cycle on a clock the caller gives, refined by the blocks the
// machine reports. ROS-free.
#pragma once

#include <cstddef>
#include <cstdint>
#include <istream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/cell/cell_rules.h"
#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace cell
{
/// \brief What a machine takes for the things a program asks: lengths in mm, times in s.
struct CycleProfile
{
  double max_feed = 0.0;          ///< mm/s: a programmed feed above it runs at it (the control's cutting limit)
  double rapid_rate = 0.0;        ///< mm/s per axis: G00, and every axis' speed limit
  double acceleration = 0.0;      ///< mm/s^2 per axis
  double tool_change_time = 0.0;  ///< s per M06
  /// Share of the acceleration the planner keeps for corners (at_protocol::PlannerLimits::corner_share).
  double corner_share = 0.2;
  gcode::Dialect dialect = gcode::Dialect::kHaas;
  /// Tool radii for a program with cutter compensation (G41/G42); none: such a program is refused.
  std::shared_ptr<const gcode::ToolTable> tool_table;

  /// \throws ConfigError naming the field that is not a positive number (tool_change_time may be 0).
  void validate() const;
};

/// \brief One block of the program as the machine runs it: a subprogram's block run three times is
/// three of these.
struct PlannedBlock
{
  uint32_t line = 0;      ///< 1-based source line
  double start = 0.0;     ///< s from the cycle's start
  double duration = 0.0;  ///< s: its moves, dwell or tool change (0 for a block that takes no time)
};

/// \brief A program planned block by block. What is not counted: M00/M01 stops (they last until
/// the operator resumes), spindle and coolant changes, the control's block processing time.
class CyclePlan
{
 public:
  /// \brief Plans \p program under \p profile; \p name names it in errors.
  /// \throws ConfigError for an invalid profile or a feed move with no feed programmed,
  /// gcode::ParseError for what the parser refuses (macros, unknown codes), naming the line.
  static CyclePlan plan(std::istream& program, const CycleProfile& profile, const std::string& name);

  /// s from the cycle's start to the program's end.
  double total() const { return total_; }
  const std::vector<PlannedBlock>& blocks() const { return blocks_; }
  /// \brief The first block from index \p from on at source line \p line, else the first from
  /// there on whose line comes after it (a reported line that takes no time, e.g. a comment).
  std::optional<size_t> find(uint32_t line, size_t from = 0) const;
  /// s left when block \p index starts.
  double remainingFrom(size_t index) const { return total_ - blocks_.at(index).start; }

 private:
  class Builder;  // cycle_time.cpp
  std::vector<PlannedBlock> blocks_;
  double total_ = 0.0;
};

/// \brief The time left in one running cycle. The plan's clock runs only while the machine runs
/// (not in a feed hold); a reported block moves it into that block's planned span. Times are
/// seconds on any monotonic clock the caller keeps. Not thread-safe.
class CycleCountdown
{
 public:
  /// \param start when the cycle started; \p running whether the program runs at that moment.
  CycleCountdown(std::shared_ptr<const CyclePlan> plan, double start, bool running = true);

  /// \brief The machine runs (true) or holds (false) from \p now on.
  void setRunning(bool running, double now);
  /// \brief The machine reports that it executes source line \p line at \p now. The same block
  /// reported again changes nothing. \returns false if the rest of the plan has no such line (the
  /// estimate then stays on the clock).
  bool reportBlock(uint32_t line, double now);

  /// s of the plan done at \p now.
  double progress(double now) const;
  /// s left at \p now: never below 0 (a machine slower than planned is "due now").
  double remaining(double now) const;
  const CyclePlan& plan() const { return *plan_; }
  /// The block the machine last reported (index into plan().blocks()), none before the first report.
  std::optional<size_t> reportedBlock() const { return block_; }

 private:
  double runTime(double now) const;

  std::shared_ptr<const CyclePlan> plan_;
  double anchor_progress_ = 0.0;  // plan seconds done at the anchor
  double cap_ = 0.0;              // progress never passes this (the end of the reported block)
  double run_before_ = 0.0;       // s run since the anchor before the current run began
  double run_since_ = 0.0;        // when the current run began
  bool running_ = true;
  std::optional<size_t> block_;
};

/// \brief A machine's state as far as its cycle goes (the fields of cnc_bridge/MachineState).
struct CycleObservation
{
  Link link = Link::Down;
  Execution execution = Execution::Unknown;
  std::string program;  ///< the program the machine runs, a name in the program folder; empty unknown
  uint32_t block = 0;   ///< the source line it executes, 0 unknown
};

/// \brief What is known of the time to a machine's cycle end at one moment.
struct CyclePrediction
{
  std::string program;
  double planned = std::numeric_limits<double>::quiet_NaN();    ///< s, the whole program
  double remaining = std::numeric_limits<double>::quiet_NaN();  ///< s to the program's end
  uint32_t block = 0;                                           ///< the line last refined from, 0: the clock only
  std::string reason;                                           ///< why remaining is unknown (NaN), empty when known
};

/// \brief Follows one machine's states and predicts its time to cycle end: a cycle starts when
/// the machine turns ACTIVE from a state outside a cycle (READY, STOPPED, ...), runs while ACTIVE,
/// holds while PAUSED, and ends in any other execution or when the link is not up. Its program is
/// looked up in the program folder by the name the machine reports (as it is, then with ".nc")
/// and planned once per file version. Not thread-safe.
class CycleWatch
{
 public:
  /// \throws ConfigError for an invalid profile or a folder that does not exist.
  CycleWatch(CycleProfile profile, std::string program_dir);

  void observe(const CycleObservation& observation, double now);
  CyclePrediction predict(double now) const;

 private:
  struct Loaded;
  std::shared_ptr<const Loaded> load(const std::string& program);
  void startCycle(const CycleObservation& observation, double now, bool start_known);

  CycleProfile profile_;
  std::string program_dir_;
  bool seen_ = false;  // a state outside a cycle seen since the start (or the link came up)
  bool in_cycle_ = false;
  bool start_known_ = false;
  std::shared_ptr<const Loaded> loaded_;  // the cycle's program, planned or its error
  std::optional<CycleCountdown> countdown_;
  bool anchored_ = false;  // the countdown has a known start or a reported block
  std::shared_ptr<const Loaded> cache_;
};
}  // namespace cell
}  // namespace cnc_bridge
