// The deadman of a jog: motion that a remote client started continues only while the client keeps
// asking for it, as teleoperation commands do (a velocity command that is not repeated within its
// timeout stops the robot). The '@' protocol has no such timeout of its own: a jog feed stays in
// force on the controller until the next one, so the host stops a jog whose client went silent.
// This file holds the timing rule, free of ROS and of any timer, so it is tested on its own.
#pragma once

#include <chrono>
#include <mutex>
#include <string>

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
}  // namespace at_protocol
}  // namespace cnc_bridge
