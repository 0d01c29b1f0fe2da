// A machine's jobs between and around their segments (job_runner.h).
#include "cnc_bridge/common/job_runner.h"

#include <utility>

namespace cnc_bridge
{
JobRunner::JobRunner(SafetySwitch& motion, Names names, ResumeRefusal resume_refusal,
                     std::chrono::milliseconds cancel_poll)
    : motion_(motion),
      names_(std::move(names)),
      resume_refusal_(std::move(resume_refusal)),
      cancel_poll_(cancel_poll),
      hold_(cancel_poll)
{
  if (!resume_refusal_)
  {
    resume_refusal_ = [this] { return motion_.enabled() ? std::string() : motion_.refusal("resume"); };
  }
}

JobRunner::Scope::Scope(JobRunner& runner) : runner_(runner)
{
  std::lock_guard<std::mutex> lock(runner_.mutex_);
  runner_.job_running_ = true;
  runner_.motion_hold_.clear();
}

JobRunner::Scope::~Scope()
{
  std::lock_guard<std::mutex> lock(runner_.mutex_);
  runner_.job_running_ = false;
  runner_.motion_hold_.clear();
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
  std::lock_guard<std::mutex> lock(mutex_);
  if (job_running_ && motion_hold_.empty())
  {
    motion_hold_ = what;
  }
  return job_running_;
}

std::string JobRunner::motionHold() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return motion_hold_;
}

bool JobRunner::startSegment(const std::function<void()>& start, JobListener& listener)
{
  for (;;)
  {
    std::string hold;
    uint64_t resumes = 0;
    {
      const auto gate = motion_.gate();
      {
        std::lock_guard<std::mutex> lock(mutex_);
        hold = motion_hold_;
        resumes = motion_resumes_;
      }
      if (motion_.enabled() && hold.empty())
      {
        start();
        return true;
      }
    }
    if (hold.empty())
    {
      hold = "motion disabled";  // the switch's listener has not named the caller yet
    }
    listener.motionHeld(hold);
    if (!waitForMotionResume(resumes, listener))
    {
      return false;
    }
    listener.motionResumed(hold);
  }
}

// Waits until a resume after \p resumes (a count read with the hold).
bool JobRunner::waitForMotionResume(uint64_t resumes, JobListener& listener)
{
  std::unique_lock<std::mutex> lock(mutex_);
  while (motion_resumes_ == resumes)
  {
    const uint64_t wakes = wakes_;
    lock.unlock();
    if (listener.cancelRequested())
    {
      return false;
    }
    lock.lock();
    // A cancel comes without a notification: look again at least every poll period.
    motion_resumed_.wait_for(lock, cancel_poll_, [&] { return motion_resumes_ != resumes || wakes_ != wakes; });
  }
  return true;
}

// ---- from other threads ---------------------------------------------------------------------------

std::string JobRunner::releaseHolds()
{
  std::string held;
  if (const std::optional<std::string> stop = hold_.resume())
  {
    held = "the " + *stop;
  }
  std::string motion;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    motion.swap(motion_hold_);
    ++motion_resumes_;
  }
  motion_resumed_.notify_all();
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
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakes_;
  }
  motion_resumed_.notify_all();
}
}  // namespace cnc_bridge
