// One ethernut job on the board (job_streamer.h).
#include "cnc_bridge/ethernut/job_streamer.h"

#include <chrono>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace ethernut
{
/// One job's state while it streams.
struct JobStreamer::Run
{
  Client& client;
  const std::shared_ptr<Job>& job;
  StreamListener& listener;
  JobFeedback feedback;
  StreamProgress totals;  ///< done and resends: the segments before the one streaming now
  bool cancelled = false;
};

JobStreamer::JobStreamer(SafetySwitch& motion, JobRunner::Names names) : runner_(motion, std::move(names)) {}

StreamOutcome JobStreamer::run(Client& client, const std::shared_ptr<Job>& job, StreamListener& listener)
{
  struct Running
  {
    JobStreamer& streamer;
    Running(JobStreamer& s, const std::shared_ptr<Job>& job) : streamer(s)
    {
      std::lock_guard<std::mutex> lock(streamer.mutex_);
      streamer.job_ = job;
    }
    ~Running()
    {
      std::lock_guard<std::mutex> lock(streamer.mutex_);
      streamer.job_.reset();
    }
  } running(*this, job);
  Run run{client, job, listener, {}, {}, false};
  run.totals.count = job->coordinateCount();
  const auto ended = [&](StreamOutcome::End end, const std::string& message)
  {
    StreamOutcome outcome;
    outcome.end = end;
    outcome.message = message;
    outcome.done = run.totals.done;
    outcome.count = run.totals.count;
    outcome.resends = run.totals.resends;
    return outcome;
  };
  for (;;)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      segment_ = Segment();
    }
    job->startSegment();
    try
    {
      if (!startSegment(run))
      {
        return ended(StreamOutcome::End::kCancelled, "cancelled while held (" + run.feedback.event + ")");
      }
    }
    catch (const Error& e)
    {
      StreamOutcome failed;  // nothing of this segment streamed: no counts
      failed.end = StreamOutcome::End::kAborted;
      failed.message = e.what();
      return failed;
    }
    const Segment segment = followSegment(run);
    run.totals.done += segment.done;
    run.totals.resends += segment.resends;
    const auto step = segment.outcome == JobOutcome::kCompleted ? job->stepAtEnd() : std::nullopt;
    if (!step || step->kind == gcode::ProgramStep::Kind::kEnd)
    {
      return finish(run, segment, step);
    }
    if (!runner_.carryOut(*step, run.feedback, listener))
    {
      StreamOutcome outcome = ended(StreamOutcome::End::kCancelled, "cancelled at the " + step->describe());
      outcome.cancelled_at_step = true;
      return outcome;
    }
  }
}

// Starts the next segment once motion may move (JobRunner::startSegment), showing a hold.
// \returns false if the job was cancelled while held. \throws Error from Client::startJob.
bool JobStreamer::startSegment(Run& run)
{
  // The runner's calls while it holds the segment, as motion holds of this job.
  class Holds : public JobListener
  {
   public:
    Holds(JobStreamer& streamer, Run& run) : streamer_(streamer), run_(run) {}
    bool cancelRequested() override { return run_.listener.cancelRequested(); }
    void motionHeld(const std::string& hold) override { streamer_.showMotionHold(run_, hold, "", false); }
    void motionResumed(const std::string& hold) override { streamer_.showMotionHold(run_, "", hold, false); }

   private:
    JobStreamer& streamer_;
    Run& run_;
  } holds(*this, run);
  const std::shared_ptr<Job> job = run.job;
  // The source keeps the job alive for as long as the client holds it.
  return runner_.startSegment([&] { run.client.startJob([job](Coordinate& out) { return job->next(out); }); }, holds);
}

// Feedback for a motion hold that began (\p hold) or ended (\p hold empty, \p ended the hold that ended).
void JobStreamer::showMotionHold(Run& run, const std::string& hold, const std::string& ended, bool board_holds)
{
  const JobRunner::Names& names = runner_.names();
  run.feedback.paused = !hold.empty();
  if (hold.empty())
  {
    run.feedback.event = "resumed after the hold (" + ended + ")";
  }
  else
  {
    run.feedback.event = hold + ": " +
                         (board_holds ? "the board holds the move in progress" : "the job holds before its next move") +
                         "; enable motion with " + names.set_motion_enabled +
                         " (std_srvs/SetBool, data: true), then call " + names.resume;
  }
  run.listener.motionHoldChanged(run.feedback, board_holds);
}

// Streams one segment to its end, with progress at most every 50 ms (a fast board acknowledges
// thousands of sets per second); a cancel holds the board, then stops streaming.
JobStreamer::Segment JobStreamer::followSegment(Run& run)
{
  uint64_t reported = UINT64_MAX;
  std::string shown_hold;  // the motion hold the last feedback showed
  for (;;)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, std::chrono::milliseconds(50), [&] { return segment_.finished; });
    Segment segment = segment_;
    lock.unlock();
    const std::string hold = runner_.motionHold();
    if (hold != shown_hold && !segment.finished)
    {
      showMotionHold(run, hold, shown_hold, true);
      shown_hold = hold;
    }
    if (segment.done != reported && (segment.done > 0 || run.totals.done == 0))
    {
      reported = segment.done;
      StreamProgress progress;
      progress.done = run.totals.done + segment.done;
      progress.count = run.totals.count;
      progress.line = segment.line;
      progress.resends = run.totals.resends + segment.resends;
      progress.last = segment.last;
      run.feedback.paused = !shown_hold.empty();
      run.listener.progress(progress, run.feedback);
    }
    if (segment.finished)
    {
      return segment;
    }
    if (!run.cancelled && run.listener.cancelRequested())
    {
      run.cancelled = true;
      cancelSegment(run.client);
    }
  }
}

// Cancel: hold the board first (it stops the move in progress), then stop streaming.
void JobStreamer::cancelSegment(Client& client)
{
  try
  {
    client.pause();
  }
  catch (const Error& e)
  {
    CNC_LOG_WARN("run_job: pause on cancel failed: " << e.what());
  }
  client.cancelJob();
}

// Ends the job after its last segment: \p step is the program's end (M02/M30) if it has one.
StreamOutcome JobStreamer::finish(Run& run, const Segment& last, const std::optional<gcode::ProgramStep>& step)
{
  StreamOutcome outcome;
  outcome.done = run.totals.done;
  outcome.count = run.totals.count;
  outcome.resends = run.totals.resends;
  outcome.message = step ? step->describe() + ": the job ends here; nothing after it was sent" : last.message;
  if (!run.job->skippedSummary().empty())
  {
    outcome.message += "; " + run.job->skippedSummary();
  }
  outcome.program_end = step.has_value();
  outcome.completed = last.outcome == JobOutcome::kCompleted;
  outcome.end = run.cancelled       ? StreamOutcome::End::kCancelled
                : outcome.completed ? StreamOutcome::End::kSucceeded
                                    : StreamOutcome::End::kAborted;
  return outcome;
}

std::string JobStreamer::releaseHolds()
{
  std::string held = runner_.releaseHolds();
  changed_.notify_all();  // followSegment() shows the hold's end
  return held;
}

// ---- the client's job events ----------------------------------------------------------------------

void JobStreamer::onCoordinateDone(uint64_t index, const Coordinate& c)
{
  std::lock_guard<std::mutex> lock(mutex_);
  segment_.done = index + 1;
  segment_.line = c.tag;
  segment_.last = c;
}

void JobStreamer::onResend()
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++segment_.resends;
}

bool JobStreamer::onJobFinished(JobOutcome outcome, const std::string& message)
{
  bool segment_continues = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    segment_.finished = true;
    segment_.outcome = outcome;
    segment_.message = message;
    segment_continues = job_ && job_->segmentContinues();
  }
  changed_.notify_all();
  return outcome == JobOutcome::kCompleted && segment_continues;
}
}  // namespace ethernut
}  // namespace cnc_bridge
