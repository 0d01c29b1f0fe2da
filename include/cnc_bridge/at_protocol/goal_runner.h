// One follow_path goal carried out on the controller (docs/at_controller_node.md, the action): its
// operations streamed one after the other, the program's own steps between them (M00 and M01 hold
// the goal until resume, G04 waits, M02/M30 end it), and a disable of motion that pauses the goal
// (the operation decelerates to a stop and holds; after resume the rest of the path is planned
// from the stop point). An operation has ended when the controller reports its end point, not when
// its last setpoint leaves (EndConfirmation). ROS-free: the node maps its listener's calls to
// feedback and state.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/common/job_runner.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief What the goal shows besides its progress (the action's feedback fields of that name).
using GoalFeedback = JobFeedback;

/// \brief When an operation counts as ended (docs/at_controller_node.md, ~end_tolerance and ~end_timeout).
struct EndCheck
{
  double tolerance = 5.0;  ///< pulses (1 um): the reported position's greatest distance from the end point
  double timeout = 2.0;    ///< s after the last setpoint that the controller has to report it
};

/// \brief The rule that an operation reached its end: the protocol has no end-of-path report, so
/// the controller's position report, received after the operation's last setpoint was sent (any
/// report if the operation does not move), within EndCheck::tolerance of the end point, within
/// EndCheck::timeout of that setpoint. Pure: the goal runner gives it the session's snapshots.
class EndConfirmation
{
 public:
  using Clock = std::chrono::steady_clock;
  /// \param end the operation's end point (pulses); \param last_setpoint when its last setpoint
  /// was written; \param moves whether the operation moves the axes at all.
  EndConfirmation(const std::array<int32_t, 3>& end, EndCheck check, Clock::time_point last_setpoint, bool moves);

  /// Whether \p now holds a position report that tells where the axes went after the last setpoint.
  bool fresh(const ControllerSnapshot& now) const;
  /// Pulses from the reported position to the end point.
  double distance(const ControllerSnapshot& now) const;
  bool confirmedBy(const ControllerSnapshot& now) const { return fresh(now) && distance(now) <= check_.tolerance; }
  Clock::time_point deadline() const;

  /// "waiting for the controller to report the end point X10 Y10 Z-1 mm (within 5 um): its last
  /// report is 49 um from it" (feedback while it waits).
  std::string waiting(const ControllerSnapshot& now) const;
  /// "the controller reported the end point X10 Y10 Z-1 mm (0 um from it) 0.031 s after the last setpoint"
  std::string confirmed(const ControllerSnapshot& now) const;
  /// Why the wait failed at the deadline: how far the last report is from the end point, and for
  /// how long it waited; \p tolerance_setting and \p timeout_setting name the parameters.
  std::string failure(const ControllerSnapshot& now, const std::string& tolerance_setting,
                      const std::string& timeout_setting) const;

 private:
  std::string endPoint() const;

  std::array<int32_t, 3> end_;
  EndCheck check_;
  Clock::time_point last_setpoint_;
  bool moves_;
};

/// \brief Calls of a running goal, on the goal's thread; the program's steps and holds are the
/// job runner's (JobListener: cancelRequested, optionalStop, dwelling, optionalStopPassed, holding).
class GoalListener : public JobListener
{
 public:
  /// An operation was taken by the sender and streams.
  virtual void operationStarted(const Operation& operation) {}
  /// Every 100 ms while an operation streams, and once at its end.
  virtual void operationProgress(const Job& job, bool stopping, const GoalFeedback& feedback) {}
  /// An operation ended (before the goal goes on, holds or ends).
  virtual void operationEnded(const OperationResult& result) {}
  /// Its last setpoint sent, the goal waits for the controller to report the operation's end point
  /// (feedback.event says how far it is): when the wait starts and at each report outside the tolerance.
  virtual void awaitingEnd(const GoalFeedback& feedback) {}
};

/// \brief How a goal ended.
struct GoalOutcome
{
  enum class End
  {
    kSucceeded,  ///< every operation reached its end (or the program ended it: program_end)
    kCancelled,  ///< cancelled: during an operation (it decelerated to a stop), or while held
    kAborted     ///< an e-stop, a lost command link, the e-stop refused the next operation, or the
                 ///< controller did not report an operation's end point (EndConfirmation)
  };
  End end = End::kSucceeded;
  std::string message;               ///< the last operation's outcome, or why the goal ended so
  bool program_end = false;          ///< succeeded at the program's M02/M30 (message says so)
  bool held_when_cancelled = false;  ///< cancelled while nothing moved: nothing more was sent
  uint64_t setpoints = 0;
  uint64_t underruns = 0;
  /// The reported position after the last operation (none if no operation ran): on success the
  /// report that confirmed the end point.
  std::optional<std::array<int32_t, 3>> final_position;
};

/// \brief Runs follow_path goals on a session, one at a time, and answers resume; the program's
/// steps, the holds and resume are the JobRunner's. Thread-safe: run() on the goal's thread,
/// resume() and wake() from any other.
class GoalRunner
{
 public:
  /// Names the node's interface has for texts ("waiting for /at_mill/resume").
  struct Names
  {
    std::string resume = "resume";
    std::string set_motion_enabled = "set_motion_enabled";
    std::string optional_stop = "optional_stop";
    std::string end_tolerance = "end_tolerance";
    std::string end_timeout = "end_timeout";
  };

  GoalRunner(ControllerSession& session, Names names, EndCheck end_check = {});

  /// \brief Carries out \p plans (ControllerSession::planGoal) of a goal with tool \p goal_tool
  /// (-1: none) of length \p goal_tool_length (m).
  /// \throws Error as ControllerSession::operationFor and runOperation (the goal then fails).
  GoalOutcome run(const std::vector<OperationPlan>& plans, int32_t goal_tool, double goal_tool_length,
                  GoalListener& listener);

  /// \brief A goal held at the program's M00/M01, or paused by a disable, goes on, if motion may
  /// start. \returns "resumed after the M00 program stop at line 7", or the refusal.
  Answer resume();
  /// \brief Makes a waiting goal ask cancelRequested() at once (shutdown).
  void wake() { jobs_.wake(); }

 private:
  struct Run;
  bool runPlan(Run& run, const OperationPlan& plan);
  bool runOperation(Run& run, const OperationPlan& plan, std::optional<DisabledStop>& stop);
  bool confirmEnd(Run& run, const OperationPlan& plan, const Job& job);

  ControllerSession& session_;
  const Names names_;
  const EndCheck end_check_;
  JobRunner jobs_;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
