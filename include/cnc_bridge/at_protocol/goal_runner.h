// One follow_path goal carried out on the controller (docs/at_controller_node.md, the action): its
// operations streamed one after the other, the program's own steps between them (M00 and M01 hold
// the goal until resume, G04 waits, M02/M30 end it), and a disable of motion that pauses the goal
// (the operation decelerates to a stop and holds; after resume the rest of the path is planned
// from the stop point). ROS-free: the node maps its listener's calls to feedback and state.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/common/job_hold.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief What the goal shows besides its progress (the action's feedback fields of that name).
struct GoalFeedback
{
  std::string event;  ///< the last program step, hold or pause, in words ("" before any)
  bool paused = false;
};

/// \brief Calls of a running goal, on the goal's thread.
class GoalListener
{
 public:
  virtual ~GoalListener() = default;
  /// Whether the goal is to stop (a cancel, shutdown); polled while it streams or waits.
  virtual bool cancelRequested() = 0;
  /// Whether M01 stops (the operator's OPT STOP switch), asked at each M01.
  virtual bool optionalStop() { return true; }
  /// An operation was taken by the sender and streams.
  virtual void operationStarted(const Operation& operation) {}
  /// Every 100 ms while an operation streams, and once at its end.
  virtual void operationProgress(const Job& job, bool stopping, const GoalFeedback& feedback) {}
  /// An operation ended (before the goal goes on, holds or ends).
  virtual void operationEnded(const OperationResult& result) {}
  /// A G04 dwell starts (feedback.event names it).
  virtual void dwelling(const GoalFeedback& feedback) {}
  /// An M01 passed because optionalStop() said no (feedback.event says so).
  virtual void optionalStopPassed(const GoalFeedback& feedback) {}
  /// The goal holds until resume (feedback.paused, event ends "waiting for <resume>"); \p line is
  /// the program line of a stop (M00, M01), 0 for a pause by a disable.
  virtual void holding(const GoalFeedback& feedback, uint32_t line) {}
};

/// \brief How a goal ended.
struct GoalOutcome
{
  enum class End
  {
    kSucceeded,  ///< every operation reached its end (or the program ended it: program_end)
    kCancelled,  ///< cancelled: during an operation (it decelerated to a stop), or while held
    kAborted     ///< an e-stop, a lost command link, or the e-stop refused the next operation
  };
  End end = End::kSucceeded;
  std::string message;               ///< the last operation's outcome, or why the goal ended so
  bool program_end = false;          ///< succeeded at the program's M02/M30 (message says so)
  bool held_when_cancelled = false;  ///< cancelled while nothing moved: nothing more was sent
  uint64_t setpoints = 0;
  uint64_t underruns = 0;
  /// The reported position after the last operation (none if no operation ran).
  std::optional<std::array<int32_t, 3>> final_position;
};

/// \brief Runs follow_path goals on a session, one at a time, and answers resume. Thread-safe:
/// run() on the goal's thread, resume() and wake() from any other.
class GoalRunner
{
 public:
  /// Names the node's interface has for texts ("waiting for /at_mill/resume").
  struct Names
  {
    std::string resume = "resume";
    std::string set_motion_enabled = "set_motion_enabled";
    std::string optional_stop = "optional_stop";
  };

  GoalRunner(ControllerSession& session, Names names);

  /// \brief Carries out \p plans (ControllerSession::planGoal) of a goal with tool \p goal_tool
  /// (-1: none) of length \p goal_tool_length (m).
  /// \throws Error as ControllerSession::operationFor and runOperation (the goal then fails).
  GoalOutcome run(const std::vector<OperationPlan>& plans, int32_t goal_tool, double goal_tool_length,
                  GoalListener& listener);

  /// \brief A goal held at the program's M00/M01, or paused by a disable, goes on, if motion may
  /// start. \returns "resumed after the M00 program stop at line 7", or the refusal.
  Answer resume();
  /// \brief Makes a waiting goal ask cancelRequested() at once (shutdown).
  void wake() { hold_.wake(); }

 private:
  struct Run;
  bool runPlan(Run& run, const OperationPlan& plan);
  bool runOperation(Run& run, const OperationPlan& plan, std::optional<DisabledStop>& stop);
  bool carryOut(Run& run, const gcode::ProgramStep& step);
  bool holdUntilResume(Run& run, const std::string& what, const std::string& event, uint32_t line);

  ControllerSession& session_;
  const Names names_;
  JobHold hold_;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
