// A running job held because motion was disabled (docs/ethernut_node.md, ~set_motion_enabled):
// a disable during a job holds it (the node pauses the board, or the job waits before its next
// segment) until motion is enabled again and the operator resumes; enabling alone moves nothing.
// The job runner's (job_runner.h: JobRunner::startSegment) hold of a disable.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>

#include "cnc_bridge/common/job_hold.h"

namespace cnc_bridge
{
/// \brief Whether a goal runs, what holds it, and the resumes that end a hold. Thread-safe: the
/// motion switch's and the resume service's threads change it while the job's thread waits.
class MotionHold
{
 public:
  /// What holds the goal and how many resumes came so far, read together: a job that finds
  /// motion disabled without a hold (the switch's handler has not run yet) waits for a resume
  /// after this count.
  struct Snapshot
  {
    std::string hold;  ///< "" when nothing holds the goal
    uint64_t resumes = 0;
  };

  /// \param cancel_poll how often waitForResume() asks its `cancelled` at the latest.
  explicit MotionHold(std::chrono::milliseconds cancel_poll = std::chrono::milliseconds(20));

  /// \brief A goal starts (true) or ends (false); either way no hold is left.
  void setGoalRunning(bool running);
  /// \brief Motion was disabled by \p what ("motion disabled by /operator"): a running goal is held
  /// by it, unless a hold already names an earlier disable. \returns true if a goal runs.
  bool disable(const std::string& what);
  /// \returns what holds the goal, "" for nothing.
  std::string hold() const;
  Snapshot snapshot() const;
  /// \brief The operator resumes: ends the hold, if any, and counts the resume.
  /// \returns the hold it ended, "" for none.
  std::string resume();
  /// \brief Waits until a resume after \p resumes (a Snapshot's count).
  /// \returns false when \p cancelled said so first (asked at least every poll period).
  bool waitForResume(uint64_t resumes, const JobHold::Cancelled& cancelled);

 private:
  std::chrono::milliseconds cancel_poll_;
  mutable std::mutex mutex_;
  std::condition_variable resumed_;
  bool goal_running_ = false;
  std::string hold_;
  uint64_t resumes_ = 0;
};
}  // namespace cnc_bridge
