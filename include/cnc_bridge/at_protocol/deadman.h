// The deadman of a jog: motion that a remote client started continues only while the client keeps
// asking for it, as teleoperation commands do (a velocity command that is not repeated within its
// timeout stops the robot). The '@' protocol has no such timeout of its own: a jog feed stays in
// force on the controller until the next one, so the host stops a jog whose client went silent.
// This file holds the timing rule (Deadman, tested on its own) and the thread that applies it in
// time (DeadmanTimer), free of ROS.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief Expiry of a motion that must be renewed. Thread-safe.
///
/// renew() arms it until `timeout` after that call; expire() reports, once, that the last renewal
/// is `timeout` or more ago. A timeout of zero disables it: it never arms, so never expires.
class Deadman
{
 public:
  using Clock = std::chrono::steady_clock;

  /// \param timeout_s seconds a renewal lasts; 0 disables the deadman.
  /// \throws ConfigError if \p timeout_s is negative or not a number.
  explicit Deadman(double timeout_s);

  bool enabled() const { return timeout_.count() > 0; }
  Clock::duration timeout() const { return timeout_; }

  /// \brief A command arrived at \p now: armed until now + timeout (no effect when disabled).
  void renew(Clock::time_point now);
  /// \brief The motion ended another way (stopped, mode changed, motion disabled): nothing to expire.
  void disarm();
  bool armed() const;

  /// \returns true exactly once per arming, when \p now is at or past the last renewal + timeout
  /// (it is then disarmed). Otherwise false, and \p remaining (if given) is the time left until it
  /// would expire (zero when not armed).
  bool expire(Clock::time_point now, Clock::duration* remaining = nullptr);

  /// \returns "no jog command for 0.5 s" for \p what "jog command".
  std::string describe(const std::string& what) const;

 private:
  Clock::duration timeout_;
  mutable std::mutex mutex_;
  bool armed_ = false;
  Clock::time_point deadline_;
};

/// \brief A thread that looks at a deadman when its deadline may have come, on the steady clock
/// (a change of the system time neither fires nor delays it).
///
/// \p check runs on the timer's thread once at start(), after each poke() and when the time it
/// last returned has passed; it returns the time until it is to run again, zero for "not until
/// the next poke()" (nothing armed).
class DeadmanTimer
{
 public:
  using Check = std::function<Deadman::Clock::duration()>;

  explicit DeadmanTimer(Check check);
  ~DeadmanTimer();
  DeadmanTimer(const DeadmanTimer&) = delete;
  DeadmanTimer& operator=(const DeadmanTimer&) = delete;

  void start();
  /// \brief Joins the thread: no check runs after it returns.
  void stop();
  /// \brief A deadline was set or moved: check at once.
  void poke();

 private:
  void run();

  Check check_;
  std::mutex mutex_;  // guards poked_, stopping_
  std::condition_variable changed_;
  bool poked_ = false;
  bool stopping_ = false;
  std::thread thread_;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
