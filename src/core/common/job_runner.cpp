// A machine's jobs between and around their segments (job_runner.h).
#include "cnc_bridge/common/job_runner.h"

#include <optional>
#include <utility>

namespace cnc_bridge
{
JobRunner::JobRunner(SafetySwitch& motion, Names names, ResumeRefusal resume_refusal,
                     std::chrono::milliseconds cancel_poll)
    : motion_(motion),
      names_(std::move(names)),
      resume_refusal_(std::move(resume_refusal)),
      hold_(cancel_poll),
      motion_hold_(cancel_poll)
{
  if (!resume_refusal_)
  {
    resume_refusal_ = [this] { return motion_.enabled() ? std::string() : motion_.refusal("resume"); };
  }
}

JobRunner::Scope::Scope(JobRunner& runner) : runner_(runner)
{
  runner_.motion_hold_.setGoalRunning(true);
}

JobRunner::Scope::~Scope()
{
  runner_.motion_hold_.setGoalRunning(false);
}

// ---- between two segments -------------------------------------------------------------------------

bool JobRunner::carryOut(const gcode::ProgramStep& step, JobFeedback& feedback, JobListener& listener)
{
  using Kind = gcode::ProgramStep::Kind;
  listener.stepReached(step);
  feedback.event = step.describe();
  feedback.paused = false;
  switch (step.kind)
  {
    case Kind::kDwell:
      listener.dwelling(feedback);
      return hold_.waitFor(std::chrono::duration<double>(step.dwell_s), [&] { return listener.cancelRequested(); });
    case Kind::kOptionalStop:
      // Asked at each M01, as an operator flips the control's OPT STOP switch during a job.
      if (!listener.optionalStop())
      {
        feedback.event += " passed (" + names_.optional_stop + " false)";
        listener.optionalStopPassed(feedback);
        return true;
      }
      return holdUntilResume(step.describe(), step.describe(), step.line, feedback, listener);
    case Kind::kStop:
      return holdUntilResume(step.describe(), step.describe(), step.line, feedback, listener);
    default:
      // Tool, spindle, coolant: the machine carries them out with its moves; the end ends the job
      // where the caller reads it.
      listener.stepDone(step, feedback);
      return true;
  }
}

bool JobRunner::holdUntilResume(const std::string& what, const std::string& event, uint32_t line, JobFeedback& feedback,
                                JobListener& listener)
{
  feedback.event = event + ": waiting for " + names_.resume;
  feedback.paused = true;
  hold_.hold(what);  // before anyone hears of the hold, so that a resume in answer finds it
  listener.holding(feedback, line);
  const bool resumed = hold_.waitForResume([&] { return listener.cancelRequested(); });
  feedback.paused = false;
  if (resumed)
  {
    listener.resumed(what);
  }
  return resumed;
}

bool JobRunner::awaitMotion(JobFeedback& feedback, JobListener& listener, std::string& held_at,
                            const std::string& where)
{
  while (!motion_.enabled())
  {
    // Disabled between two segments (during a dwell or a program stop): nothing is moving.
    const std::string by = motion_.disabledBy();
    held_at = "motion disabled by " + by + " (" + names_.set_motion_enabled + ") " + where;
    if (!holdUntilResume("stop when motion was disabled by " + by, held_at, 0, feedback, listener))
    {
      return false;
    }
  }
  return true;
}

// ---- the hold of a disable ------------------------------------------------------------------------

bool JobRunner::holdOnDisable(const std::string& what)
{
  return motion_hold_.disable(what);
}

std::string JobRunner::motionHold() const
{
  return motion_hold_.hold();
}

bool JobRunner::startSegment(const std::function<void()>& start, JobListener& listener)
{
  for (;;)
  {
    MotionHold::Snapshot now;
    {
      const auto gate = motion_.gate();
      now = motion_hold_.snapshot();
      if (motion_.enabled() && now.hold.empty())
      {
        start();
        return true;
      }
    }
    // The switch's listener has not named the caller yet when the hold is still empty.
    const std::string hold = now.hold.empty() ? "motion disabled" : now.hold;
    listener.motionHeld(hold);
    if (!motion_hold_.waitForResume(now.resumes, [&] { return listener.cancelRequested(); }))
    {
      return false;
    }
    listener.motionResumed(hold);
  }
}

// ---- from other threads ---------------------------------------------------------------------------

std::string JobRunner::releaseHolds()
{
  std::string held;
  if (const std::optional<std::string> stop = hold_.resume())
  {
    held = "the " + *stop;
  }
  const std::string motion = motion_hold_.resume();
  if (!motion.empty())
  {
    held += (held.empty() ? "the hold (" : " and the hold (") + motion + ")";
  }
  return held;
}

ResumeAnswer JobRunner::resume(const std::string& nothing_held)
{
  if (hold_.held().empty() && motionHold().empty())
  {
    return ResumeAnswer{false, nothing_held};
  }
  const std::string refusal = resume_refusal_();
  if (!refusal.empty())
  {
    return ResumeAnswer{false, refusal};
  }
  const std::string held = releaseHolds();
  return held.empty() ? ResumeAnswer{false, nothing_held} : ResumeAnswer{true, "resumed after " + held};
}

void JobRunner::wake()
{
  hold_.wake();
}
}  // namespace cnc_bridge
