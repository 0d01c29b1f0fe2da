// The program's own pauses while a node streams a job: the stop (M00), the optional stop (M01,
// when the operator's switch says stop) and the dwell (G04). A stop holds the job until the
// operator lets it go on (the node's ~resume service); a dwell waits its time. Either ends early
// when the goal is cancelled. The streaming nodes (ethernut_node, at_controller_node) carry these
// out between two segments of moves (docs/ethernut_node.md, docs/at_controller_node.md); this class
// is the waiting part they share, free of ROS so unit tests reach it.
//
// A cancel (an action goal's preempt request, ROS shutting down) comes without a notification, so
// the waits ask the node's `cancelled` predicate again at least every poll period (20 ms unless
// told otherwise); wake() makes them ask at once.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

namespace cnc_bridge
{
/// \brief One job's program-step hold: a stop waiting for resume, or a dwell. Thread-safe: the
/// job's thread holds and waits; service threads call resume(), held() and wake().
///
/// A stop, in the job's thread:
/// \code
///   hold.hold(step.describe());           // from here on, resume() ends the hold
///   publishFeedback("waiting for ~resume");
///   if (!hold.waitForResume(cancelled)) { /* goal cancelled while held */ }
/// \endcode
/// and in the ~resume service: `if (auto what = hold.resume()) answer("resumed after the " + *what);`
class JobHold
{
 public:
  /// Says whether the goal was cancelled; called from the waiting thread, without a lock held.
  using Cancelled = std::function<bool()>;

  /// \param cancel_poll how often a wait asks `cancelled` at the latest.
  explicit JobHold(std::chrono::milliseconds cancel_poll = std::chrono::milliseconds(20));

  /// \brief Holds the job at \p what (e.g. "program stop M00 at line 12"): from now on held()
  /// names it and resume() ends the hold. \p what must not be empty. Call it before telling anyone that the job waits,
  /// so that a resume sent in answer finds the hold. A resume from before this call does not count.
  void hold(std::string what);

  /// \brief Waits until resume() ends the hold set by hold(), or a resume since hold() already
  /// did. The hold ends when this returns, either way (held() is then empty).
  /// \returns true when resumed, false when \p cancelled said so first (a resume wins when both
  /// came before the wait looked).
  bool waitForResume(const Cancelled& cancelled);

  /// \brief Waits \p time (a dwell); resume() does not shorten it.
  /// \returns true when the time has passed, false when \p cancelled said so first.
  bool waitFor(std::chrono::duration<double> time, const Cancelled& cancelled);

  /// \brief Ends the hold (the waiting job goes on).
  /// \returns what was held (as given to hold()), or nothing when no job is held; then nothing
  /// changes, and a later hold() is not ended by this call.
  std::optional<std::string> resume();

  /// \returns what the job is held at, "" when it is not held.
  std::string held() const;

  /// \brief Makes a waiting job ask its `cancelled` now rather than at the next poll (e.g. when the
  /// node shuts down and `cancelled` says so).
  void wake();

 private:
  std::chrono::milliseconds cancel_poll_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::string held_;      // what the job is held at, "" when not held
  bool resumed_ = false;  // resume() ended the hold held_ names
  uint64_t wakes_ = 0;    // wake() calls: a wake while a waiter asks `cancelled` is not lost
};
}  // namespace cnc_bridge
