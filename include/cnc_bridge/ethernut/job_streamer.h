// JobStreamer: one ethernut job on the board, ROS-free (docs/ethernut_node.md, ~run_job). The job
// streams as segments: the moves up to the program's next own step (stop, dwell, spindle, coolant,
// tool change), which the JobRunner carries out between two segments, or its end. A segment starts
// under the motion switch's gate once motion may move (a disable during the job holds it until
// motion is enabled and resume is called); a cancel pauses the board (it holds the move in
// progress), then stops streaming. The node forwards the client's job events (onCoordinateDone,
// onResend, onJobFinished) and maps the listener's calls to feedback and state.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "cnc_bridge/common/job_runner.h"
#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/ethernut/job.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief How far a job is: sets acknowledged of all its segments, the last of them.
struct StreamProgress
{
  uint64_t done = 0;   ///< sets acknowledged (all segments)
  uint64_t count = 0;  ///< sets in the job
  uint32_t line = 0;   ///< the program line of the last acknowledged set
  uint32_t resends = 0;
  Coordinate last;  ///< the last acknowledged set (the commanded position), mm
};

/// \brief Calls of a streaming job, on the job's thread.
class StreamListener : public JobListener
{
 public:
  /// Acknowledged progress, at most every 50 ms while a segment streams.
  virtual void progress(const StreamProgress& /*progress*/, const JobFeedback& /*feedback*/) {}
  /// A motion hold began (feedback.paused) or ended, in words (feedback.event): before the next
  /// segment (\p board_holds false: nothing streams) or during one (true: the board holds its move).
  virtual void motionHoldChanged(const JobFeedback& /*feedback*/, bool /*board_holds*/) {}
};

/// \brief How a job ended.
struct StreamOutcome
{
  enum class End
  {
    kSucceeded,
    kCancelled,
    kAborted
  };
  End end = End::kSucceeded;
  std::string message;
  uint64_t done = 0;  ///< sets acknowledged (0 with count 0: the job failed before its first set)
  uint64_t count = 0;
  uint32_t resends = 0;
  bool completed = false;          ///< the last segment streamed to its end
  bool program_end = false;        ///< ended at the program's M02/M30 (message says so)
  bool cancelled_at_step = false;  ///< cancelled while held at one of the program's own steps
};

/// \brief Streams jobs on a board, one at a time. Thread-safe: run() on the job's thread, the
/// client's events on its run() thread, the holds' calls on service threads.
class JobStreamer
{
 public:
  /// \param motion the node's motion switch; \param names the node's resume, set_motion_enabled
  /// and optional_stop, for texts.
  JobStreamer(SafetySwitch& motion, JobRunner::Names names);

  /// \brief Streams \p job on \p client to its end, a cancel (StreamListener::cancelRequested) or
  /// a failure; the program's steps between its segments are the runner's.
  StreamOutcome run(Client& client, const std::shared_ptr<Job>& job, StreamListener& listener);

  /// The runner: a node's JobRunner::Scope for the goal, holdOnDisable() from the switch's
  /// listener, motionHold().
  JobRunner& runner() { return runner_; }

  /// \brief Ends the job's holds (program stop, disable) and lets run() show it.
  /// \returns JobRunner::releaseHolds()'s text.
  std::string releaseHolds();
  /// \brief Lets run() look at the holds now (after holdOnDisable()).
  void notify() { changed_.notify_all(); }

  // ---- the client's job events (its run() thread) --------------------------------------------
  void onCoordinateDone(uint64_t index, const Coordinate& c);
  void onResend();
  /// \returns true when the job goes on after one of the program's own steps (the board's job
  /// ended, not the node's).
  bool onJobFinished(JobOutcome outcome, const std::string& message);

 private:
  // What the client reported of the segment streaming now (client thread -> job thread).
  struct Segment
  {
    uint64_t done = 0;
    uint32_t line = 0;
    uint32_t resends = 0;
    Coordinate last;
    bool finished = false;
    JobOutcome outcome = JobOutcome::kFailed;
    std::string message;
  };
  struct Run;

  bool startSegment(Run& run);
  Segment followSegment(Run& run);
  void showMotionHold(Run& run, const std::string& hold, const std::string& ended, bool board_holds);
  static void cancelSegment(Client& client);
  static StreamOutcome finish(Run& run, const Segment& last, const std::optional<gcode::ProgramStep>& step);

  JobRunner runner_;
  std::mutex mutex_;  ///< segment_, job_
  std::condition_variable changed_;
  Segment segment_;
  std::shared_ptr<const Job> job_;  ///< the running job
};
}  // namespace ethernut
}  // namespace cnc_bridge
