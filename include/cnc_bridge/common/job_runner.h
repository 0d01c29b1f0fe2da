// JobRunner: what every node that executes a program or a point list on a machine (ethernut_node,
// at_controller_node) does between and around the segments of moves it streams, written once and
// free of ROS: the program's own steps between two segments (M00 holds until resume, M01 too when
// the operator's optional stop is on, G04 waits its time, M06/M03-M05/M07-M09 are reported), the
// hold of a job whose motion was disabled, resume, cancel. How a segment streams is the
// protocol's (ethernut::Client, at_protocol::ControllerSession); what the node shows is its
// listener's (JobListener: feedback, state). The waits ask JobListener::cancelRequested() at least
// every poll period (JobHold).
//
// Two motion holds, as the machines differ:
//  - awaitMotion(): before the next segment, the job holds while motion is disabled (the '@'
//    controller: it decelerated to a stop, nothing moves; enabled and resumed, it goes on);
//  - startSegment(): a disable at any time during the job holds it until motion is enabled AND
//    resume is called, enabling alone moves nothing (the ethernut board pauses the move in progress
//    and keeps it, so the job goes on only when the operator says so).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "cnc_bridge/common/job_hold.h"
#include "cnc_bridge/common/motion_hold.h"
#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/gcode/program_steps.h"

namespace cnc_bridge
{
/// \brief What a job shows besides its progress (an action's feedback fields of that name).
struct JobFeedback
{
  std::string event;  ///< the last program step, hold or pause, in words ("" before any)
  bool paused = false;
};

/// \brief Calls of a running job, on the job's thread.
class JobListener
{
 public:
  virtual ~JobListener() = default;
  /// Whether the job is to stop (a cancel, shutdown); polled while it waits.
  virtual bool cancelRequested() = 0;
  /// Whether M01 stops (the operator's OPT STOP switch), asked at each M01.
  virtual bool optionalStop() { return true; }
  /// One of the program's own steps is reached between two segments (before it is carried out).
  virtual void stepReached(const gcode::ProgramStep& /*step*/) {}
  /// A tool change, spindle or coolant step: the machine did it with the moves before; the node shows it.
  virtual void stepDone(const gcode::ProgramStep& /*step*/, const JobFeedback& /*feedback*/) {}
  /// A G04 dwell starts (feedback.event names it).
  virtual void dwelling(const JobFeedback& /*feedback*/) {}
  /// An M01 passed because optionalStop() said no (feedback.event says so).
  virtual void optionalStopPassed(const JobFeedback& /*feedback*/) {}
  /// The job holds until resume (feedback.paused, event ends "waiting for <resume>"); \p line is
  /// the program line of a stop (M00, M01), 0 for a hold by a disable.
  virtual void holding(const JobFeedback& /*feedback*/, uint32_t /*line*/) {}
  /// A hold of holdUntilResume() ended by resume; \p what is the hold ("M00 program stop at line 7").
  virtual void resumed(const std::string& /*what*/) {}
  /// startSegment(): the job holds before its next segment because of a disable (\p hold names it).
  virtual void motionHeld(const std::string& /*hold*/) {}
  /// startSegment(): that hold ended (motion enabled and resumed).
  virtual void motionResumed(const std::string& /*hold*/) {}
};

/// \brief The answer to a resume request.
struct ResumeAnswer
{
  bool success = false;
  std::string message;
};

/// \brief One machine's jobs, one at a time: their program steps, holds and resumes. Thread-safe:
/// the job's calls on its thread, resume(), releaseHolds() and wake() from any other.
class JobRunner
{
 public:
  /// Names the node's interface has, for texts ("waiting for /cell/mill/resume").
  struct Names
  {
    std::string resume = "resume";
    std::string set_motion_enabled = "set_motion_enabled";
    std::string optional_stop = "optional_stop";
  };
  /// Why resume may not go on now ("" when it may); by default the switch's refusal while disabled.
  using ResumeRefusal = std::function<std::string()>;

  /// \param motion the node's motion switch (a disable during a job holds it; see startSegment()).
  /// \param cancel_poll how often a wait asks cancelRequested() at the latest.
  JobRunner(SafetySwitch& motion, Names names, ResumeRefusal resume_refusal = nullptr,
            std::chrono::milliseconds cancel_poll = std::chrono::milliseconds(20));
  JobRunner(const JobRunner&) = delete;
  JobRunner& operator=(const JobRunner&) = delete;

  /// \brief Marks a job as running for its scope: a disable meanwhile holds it (startSegment()).
  class Scope
  {
   public:
    explicit Scope(JobRunner& runner);
    ~Scope();
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    JobRunner& runner_;
  };

  // ---- between two segments -----------------------------------------------------------------

  /// \brief Carries out one of the program's own steps between two segments (every move before
  /// it has been made): M00 (and M01 unless optionalStop() says no) hold until resume, G04 waits
  /// its time, tool, spindle and coolant steps are reported (stepDone). Sets \p feedback.event.
  /// \returns false if the job was cancelled meanwhile.
  bool carryOut(const gcode::ProgramStep& step, JobFeedback& feedback, JobListener& listener);

  /// \brief Holds the job (nothing is sent) until resume: paused, "<event>: waiting for <resume>";
  /// \p what completes "resumed after the ..." in resume's answer. \returns false if cancelled.
  bool holdUntilResume(const std::string& what, const std::string& event, uint32_t line, JobFeedback& feedback,
                       JobListener& listener);

  /// \brief Holds while motion is disabled ("motion disabled by <who> (<set_motion_enabled>)
  /// before the next operation: waiting for <resume>"), until enabled and resumed.
  /// \returns false if cancelled while held; \p held_at is then the hold's event (without
  /// "waiting for").
  bool awaitMotion(JobFeedback& feedback, JobListener& listener, std::string& held_at,
                   const std::string& where = "before the next operation");

  // ---- the hold of a disable (the board keeps its move) --------------------------------------

  /// \brief Runs \p start under the motion switch's gate once motion may move: enabled, and no
  /// hold left from a disable during this job (resume ends it). A disable thus comes wholly before
  /// \p start (the job is held here) or after it (the switch's listeners stop the machine).
  /// \returns false if the job was cancelled while held. \p start's exceptions pass through.
  bool startSegment(const std::function<void()>& start, JobListener& listener);

  /// \brief Motion was disabled (\p what: "motion disabled by /cell_manager"): a running job is
  /// held by it (unless a hold already names an earlier disable) until releaseHolds() or resume().
  /// The node's listener of the motion switch calls it. \returns true if a job runs.
  bool holdOnDisable(const std::string& what);

  /// \returns the hold a disable put on the running job ("motion disabled by /cell_manager"),
  /// "" for none.
  std::string motionHold() const;

  // ---- from other threads --------------------------------------------------------------------

  /// \brief Ends the job's holds (a program stop, a disable's hold) without asking whether motion
  /// may start (the caller did). \returns what they were ("the M00 program stop at line 7", "the
  /// hold (motion disabled by /x)", both joined by " and "), "" for none.
  std::string releaseHolds();

  /// \brief A job held at the program's M00/M01 or by a disable goes on, if motion may start.
  /// \returns "resumed after the M00 program stop at line 7", the refusal, or \p nothing_held.
  ResumeAnswer resume(const std::string& nothing_held);

  /// \returns what the job is held at by holdUntilResume() ("" when it is not).
  std::string held() const { return hold_.held(); }

  /// \brief Makes a job waiting at a program step ask cancelRequested() at once (shutdown); a
  /// segment held by a disable asks at the next poll.
  void wake();

  const Names& names() const { return names_; }

 private:
  SafetySwitch& motion_;
  const Names names_;
  ResumeRefusal resume_refusal_;
  JobHold hold_;  ///< the program's stop (and awaitMotion()'s hold)

  MotionHold motion_hold_;  ///< a disable's hold of the running job
};
}  // namespace cnc_bridge
