// An action run every day at a local time of day (share_node's ~withdraw_at), on a thread of its
// own, against a wall clock a test can replace: the schedule is nextDailyTime() (daily_time.h),
// and a test moves its clock to the time instead of waiting for a day (docs/share_node.md).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <ctime>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>

#include "cnc_bridge/programs/daily_time.h"

namespace cnc_bridge::programs
{
/// \brief The wall clock a DailyTimer reads (seconds since the epoch; local time by TZ).
class WallClock
{
 public:
  virtual ~WallClock() = default;
  virtual std::time_t now() const = 0;
  /// \brief The system's clock, time(2).
  static std::shared_ptr<const WallClock> system();
};

/// \brief Calls an action every day when the local clock reads a time of day. The first time is
/// the next one after construction; after each run, the same time on the next date
/// (nextDailyTime() with done_today). A clock set back before the time is waited out (the action
/// does not run early); a clock set forward past it runs the action at the next look at the
/// clock, which is at the time itself or at most `recheck` later.
class DailyTimer
{
 public:
  using Action = std::function<void()>;
  /// \brief Called with each next time: at construction and after each run (from the timer's thread).
  using Scheduled = std::function<void(std::time_t next)>;

  /// \param action runs on the timer's thread; an exception it throws is logged and the timer
  ///        goes on. \param recheck longest wait between two looks at the clock.
  DailyTimer(DailyTime at, Action action, Scheduled scheduled = nullptr,
             std::shared_ptr<const WallClock> clock = WallClock::system(),
             std::chrono::milliseconds recheck = std::chrono::minutes(1));
  /// Stops the thread (waits for a running action to end).
  ~DailyTimer();
  DailyTimer(const DailyTimer&) = delete;
  DailyTimer& operator=(const DailyTimer&) = delete;

  const DailyTime& at() const { return at_; }
  /// \brief The next time the action runs (seconds since the epoch).
  std::time_t next() const;
  /// \brief How many times the action has run.
  uint64_t runs() const;
  /// \brief Makes the timer look at its clock now, and returns once it has (and has run the
  /// action, if the time had come). For a clock that was moved (tests); not from the action.
  void recheck();

 private:
  void loop();

  const DailyTime at_;
  const Action action_;
  const Scheduled scheduled_;
  const std::shared_ptr<const WallClock> clock_;
  const std::chrono::milliseconds recheck_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;     ///< the thread: a recheck or stop was asked for
  std::condition_variable checked_;  ///< recheck(): the thread has looked at the clock
  std::time_t next_ = 0;
  uint64_t runs_ = 0;
  uint64_t requested_ = 0;  ///< rechecks asked for
  uint64_t served_ = 0;     ///< rechecks done
  bool stop_ = false;
  std::thread thread_;
};
}  // namespace cnc_bridge::programs
