// A follow_path goal on the controller (goal_runner.h).
#include "cnc_bridge/at_protocol/goal_runner.h"

#include <cmath>
#include <iomanip>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// One goal's state while it runs.
struct GoalRunner::Run
{
  int32_t goal_tool;
  double goal_tool_length;
  GoalListener& listener;
  JobHold::Cancelled cancelled;
  GoalFeedback feedback;
  GoalOutcome outcome;
  std::string end_confirmed;  ///< how the last operation's end point was confirmed ("" before any)
};

namespace
{
/// \p value with \p decimals at most, without trailing zeros: 10, 10.049, 1.4.
std::string trimmed(double value, int decimals)
{
  std::ostringstream text;
  text << std::fixed << std::setprecision(decimals) << value;
  std::string out = text.str();
  if (out.find('.') != std::string::npos)
  {
    out.erase(out.find_last_not_of('0') + 1);
    if (out.back() == '.')
    {
      out.pop_back();
    }
  }
  return out == "-0" ? "0" : out;
}

/// Pulses as "X10 Y10.049 Z-1 mm".
std::string inMm(const std::array<int32_t, 3>& pulses)
{
  return "X" + trimmed(pulses[0] / kPulsesPerMm, 3) + " Y" + trimmed(pulses[1] / kPulsesPerMm, 3) + " Z" +
         trimmed(pulses[2] / kPulsesPerMm, 3) + " mm";
}

/// The goal ends PREEMPTED while nothing moves: nothing more is sent.
bool cancelledWhileHeld(GoalOutcome& outcome, const std::string& message)
{
  outcome.end = GoalOutcome::End::kCancelled;
  outcome.held_when_cancelled = true;
  outcome.message = message;
  return false;
}
}  // namespace

// ---- EndConfirmation ------------------------------------------------------------------------------

EndConfirmation::EndConfirmation(const std::array<int32_t, 3>& end, EndCheck check, Clock::time_point last_setpoint,
                                 bool moves)
    : end_(end), check_(check), last_setpoint_(last_setpoint), moves_(moves)
{
}

bool EndConfirmation::fresh(const ControllerSnapshot& now) const
{
  // A report from before the last setpoint may show the end point while the axes were elsewhere
  // since (a path that comes back to its start); one that does not move has no "after".
  return now.position_valid && (!moves_ || now.position_at > last_setpoint_);
}

double EndConfirmation::distance(const ControllerSnapshot& now) const
{
  double sum = 0.0;
  for (int i = 0; i < 3; ++i)
  {
    const double d = double(now.position[i]) - double(end_[i]);
    sum += d * d;
  }
  return std::sqrt(sum);
}

EndConfirmation::Clock::time_point EndConfirmation::deadline() const
{
  return last_setpoint_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(check_.timeout));
}

std::string EndConfirmation::endPoint() const
{
  return "the end point " + inMm(end_);
}

std::string EndConfirmation::waiting(const ControllerSnapshot& now) const
{
  const std::string far = " is " + trimmed(distance(now) / kPulsesPerMm * 1000.0, 1) + " um from it";
  return "waiting for the controller to report " + endPoint() + " (within " +
         trimmed(check_.tolerance / kPulsesPerMm * 1000.0, 1) +
         " um): " + (fresh(now) ? "its last report" + far : "no position report since the last setpoint yet");
}

std::string EndConfirmation::confirmed(const ControllerSnapshot& now) const
{
  const double after = std::chrono::duration<double>(now.position_at - last_setpoint_).count();
  return "the controller reported " + endPoint() + " (" + trimmed(distance(now) / kPulsesPerMm * 1000.0, 1) +
         " um from it)" + (moves_ ? " " + trimmed(std::max(after, 0.0), 3) + " s after the last setpoint" : "");
}

std::string EndConfirmation::failure(const ControllerSnapshot& now, const std::string& tolerance_setting,
                                     const std::string& timeout_setting) const
{
  const std::string waited = trimmed(check_.timeout, 3) + " s";
  const std::string tolerance =
      trimmed(check_.tolerance / kPulsesPerMm * 1000.0, 1) + " um (" + tolerance_setting + ")";
  const std::string far = trimmed(distance(now) / kPulsesPerMm * 1000.0, 1) + " um from it";
  std::string message = "every setpoint was sent, but the controller did not report " + endPoint() + " within " +
                        tolerance + " in the " + waited + " (" + timeout_setting + ") after the last setpoint: ";
  if (!now.position_valid)
  {
    return message + "it has reported no position at all (is the report link up?)";
  }
  if (!fresh(now))
  {
    return message + "no position report came after the last setpoint (is the report link up?); the one before, " +
           inMm(now.position) + ", is " + far;
  }
  return message + "its last report, " + inMm(now.position) + ", is " + far + " (the axes stopped short, or lag)";
}

// ---- GoalRunner -----------------------------------------------------------------------------------

GoalRunner::GoalRunner(ControllerSession& session, Names names, EndCheck end_check)
    : session_(session),
      names_(std::move(names)),
      end_check_(end_check),
      jobs_(session.motionSwitch(), JobRunner::Names{names_.resume, names_.set_motion_enabled, names_.optional_stop},
            // The e-stop (on or unknown) refuses a resume too, not only the switch.
            [this] { return session_.motionRefusal("resume"); })
{
}

GoalOutcome GoalRunner::run(const std::vector<OperationPlan>& plans, int32_t goal_tool, double goal_tool_length,
                            GoalListener& listener)
{
  Run run{goal_tool, goal_tool_length, listener, [&listener] { return listener.cancelRequested(); }, {}, {}, {}};
  try
  {
    session_.checkPlans(plans, goal_tool, goal_tool_length);  // the whole goal, before its first byte
    for (const OperationPlan& plan : plans)
    {
      if (plan.moves() && !runPlan(run, plan))
      {
        return run.outcome;  // cancelled or failed: the goal has ended
      }
      if (!plan.after)
      {
        continue;
      }
      if (plan.after->kind == gcode::ProgramStep::Kind::kEnd)
      {
        run.outcome.message = plan.after->describe() + ": the program ends here; nothing after it was sent" +
                              (run.end_confirmed.empty() ? "" : "; " + run.end_confirmed);
        run.outcome.program_end = true;
        break;
      }
      if (!jobs_.carryOut(*plan.after, run.feedback, run.listener))
      {
        cancelledWhileHeld(run.outcome, "cancelled at the " + plan.after->describe());
        return run.outcome;
      }
    }
    run.outcome.end = GoalOutcome::End::kSucceeded;
  }
  catch (const std::exception& e)
  {
    run.outcome.end = GoalOutcome::End::kAborted;
    run.outcome.message = e.what();
  }
  return run.outcome;
}

/// Runs one operation of a goal. Motion disabled before or during it pauses the goal (the path
/// decelerates to a stop and holds, the goal stays active) until motion is enabled and resume is
/// called; the rest of the path is then planned from the stop point, from rest, to its end.
/// \returns true if the operation reached its end (the goal goes on); otherwise the goal has
/// ended (cancelled, e-stop, link failure).
bool GoalRunner::runPlan(Run& run, const OperationPlan& plan)
{
  OperationPlan rest = plan;
  for (;;)
  {
    std::string held_at;
    if (!jobs_.awaitMotion(run.feedback, run.listener, held_at))
    {
      return cancelledWhileHeld(run.outcome, "cancelled while held: " + held_at);
    }
    const std::string refusal = session_.motionRefusal("follow_path");
    if (!refusal.empty())
    {
      // The e-stop (E1 or unknown) between operations: the goal cannot go on.
      run.outcome.end = GoalOutcome::End::kAborted;
      run.outcome.message =
          refusal + (run.feedback.event.empty() ? "" : " (before the operation after " + run.feedback.event + ")");
      return false;
    }
    std::optional<DisabledStop> stop;
    if (runOperation(run, rest, stop))
    {
      return true;
    }
    if (!stop)
    {
      return false;  // cancelled, e-stop or link failure: the goal has ended
    }
    std::ostringstream event;
    event << "motion disabled by " << stop->by << " (" << names_.set_motion_enabled
          << "): decelerated to a stop along the path at X" << stop->position[0] / kPulsesPerMm << " Y"
          << stop->position[1] / kPulsesPerMm << " Z" << stop->position[2] / kPulsesPerMm << " mm after " << stop->sent
          << " of " << stop->planned << " planned setpoints";
    CNC_LOG_WARN("at_controller: follow_path: " << event.str() << "; holding");
    if (!jobs_.holdUntilResume("stop when motion was disabled by " + stop->by, event.str(), 0, run.feedback,
                               run.listener))
    {
      return cancelledWhileHeld(run.outcome, "cancelled while held: " + event.str());
    }
    const PathRest left = restOfPath(rest.points, rest.feeds, stop->distance, stop->position);
    if (left.empty())
    {
      return true;  // it came to rest on the end point
    }
    rest.points = left.points;
    rest.feeds = left.feeds;
    rest.tool = -1;  // the tool was changed before the stop
  }
}

/// Runs one operation to its end. \returns true if it succeeded (the goal goes on). Otherwise
/// either \p stop says where motion was disabled (the operation decelerated to a stop and ended
/// with #@ M0@; the goal goes on, paused) or the goal has ended (cancelled, e-stop, link failure).
bool GoalRunner::runOperation(Run& run, const OperationPlan& plan, std::optional<DisabledStop>& stop)
{
  const Operation operation = session_.operationFor(plan, run.goal_tool, run.goal_tool_length);
  // The S-curve streams the trapezoid's steps plus its average's window less one.
  const size_t setpoints = TrajectoryStream(*operation.trajectory).total();
  CNC_LOG_INFO("at_controller: follow_path: "
               << plan.points.size() - 1 << " segments, " << operation.trajectory->length() / kPulsesPerMm << " mm in "
               << setpoints * session_.options().limits.period << " s (" << setpoints << " setpoints)");
  ControllerSession::OperationWatch watch;
  watch.started = [&](const Job&) { run.listener.operationStarted(operation); };
  watch.cancel_requested = run.cancelled;
  watch.progress = [&](const Job& job, bool stopping) { run.listener.operationProgress(job, stopping, run.feedback); };
  run.feedback.paused = false;
  const OperationResult result = session_.runOperation(plan, operation, watch);
  const Job& job = *result.job;
  run.outcome.setpoints += job.sent();
  run.outcome.underruns += result.underruns;
  run.outcome.final_position = session_.snapshot().position;
  run.outcome.message = job.message();
  run.listener.operationEnded(result);
  stop = result.disabled;
  if (stop)
  {
    return false;
  }
  switch (job.state())
  {
    case Job::State::kSucceeded:
      return confirmEnd(run, plan, job);
    case Job::State::kCancelled:
      run.outcome.end = GoalOutcome::End::kCancelled;
      return false;
    case Job::State::kFailed:
      // The protocol has no host watchdog: the controller holds the last setpoint it received.
      run.outcome.end = GoalOutcome::End::kAborted;
      run.outcome.message = "command link lost after " + std::to_string(job.sent()) + " setpoints: " + job.message() +
                            "; the controller holds the last setpoint it received, the node reconnects (send the "
                            "rest as a new goal)";
      return false;
    default:
      run.outcome.end = GoalOutcome::End::kAborted;
      return false;
  }
}

/// Waits after an operation's last setpoint until the controller reports its end point
/// (EndConfirmation); the outcome's final_position is that report. \returns true if it did; else
/// the goal has ended: ABORTED when it did not within the timeout or an e-stop came, PREEMPTED
/// when cancelled meanwhile.
bool GoalRunner::confirmEnd(Run& run, const OperationPlan& plan, const Job& job)
{
  const Vec3& last = plan.points.back();  // whole pulses (roundToPulses)
  const std::array<int32_t, 3> end{static_cast<int32_t>(last[0]), static_cast<int32_t>(last[1]),
                                   static_cast<int32_t>(last[2])};
  const bool sent = job.sent() > 0;
  const EndConfirmation confirmation(end, end_check_, sent ? job.lastSetpointAt() : EndConfirmation::Clock::now(),
                                     sent && job.operation().trajectory->length() > 0.0);
  const std::string last_step = run.feedback.event;  // the program's last own step, kept
  ControllerSnapshot now = session_.snapshot();
  while (!confirmation.confirmedBy(now))
  {
    run.feedback.event = confirmation.waiting(now);
    run.listener.awaitingEnd(run.feedback);
    const auto seen = now.position_at;
    // Until the next position report, an e-stop, a cancel or the deadline.
    now = session_.waitForReport([&](const ControllerSnapshot& s)
                                 { return s.position_at != seen || s.estop == EStop::kOn; },
                                 confirmation.deadline(), run.cancelled);
    run.outcome.final_position = now.position;
    if (confirmation.confirmedBy(now))
    {
      break;
    }
    if (now.estop == EStop::kOn)
    {
      run.outcome.end = GoalOutcome::End::kAborted;
      run.outcome.message = "emergency stop reported by the controller (E1) before it reported the end point: " +
                            confirmation.waiting(now);
      return false;
    }
    if (run.cancelled())
    {
      run.outcome.end = GoalOutcome::End::kCancelled;
      run.outcome.message = "cancelled after the last setpoint, while " + confirmation.waiting(now);
      return false;
    }
    if (EndConfirmation::Clock::now() >= confirmation.deadline())
    {
      run.outcome.end = GoalOutcome::End::kAborted;
      run.outcome.message = confirmation.failure(now, names_.end_tolerance, names_.end_timeout);
      return false;
    }
  }
  run.outcome.final_position = now.position;
  run.end_confirmed = confirmation.confirmed(now);
  run.outcome.message = job.message() + ": " + run.end_confirmed;
  run.feedback.event = last_step;
  return true;
}

Answer GoalRunner::resume()
{
  const ResumeAnswer answer = jobs_.resume(
      "nothing to resume: no follow_path goal is held (at a program stop M00/M01, or paused by motion disabled)");
  return Answer{answer.success, answer.message};
}
}  // namespace at_protocol
}  // namespace cnc_bridge
