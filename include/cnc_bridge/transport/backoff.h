// Reconnecting without hammering a machine that is switched off: capped exponential backoff, an
// interruptible wait (so shutdown never waits out a backoff), and a loop that keeps one link up.
#pragma once

#include <atomic>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief Delays of initial, initial*factor, ... capped at maximum. Not thread-safe.
class Backoff
{
 public:
  Backoff(Milliseconds initial = Milliseconds(250), Milliseconds maximum = Milliseconds(10000), double factor = 2.0);
  /// \returns the delay to wait before the next attempt, and grows the following one.
  Milliseconds next();
  /// \brief Back to the initial delay (after a success).
  void reset();
  unsigned failures() const { return failures_; }

 private:
  Milliseconds initial_;
  Milliseconds maximum_;
  double factor_;
  Milliseconds current_;
  unsigned failures_ = 0;
};

/// \brief A flag that can be waited on: stop() wakes every waiter at once. Thread-safe.
class StopSignal
{
 public:
  void stop();
  bool stopped() const { return stopped_; }
  /// \returns true if stop() was called before \p timeout elapsed.
  bool waitFor(Milliseconds timeout);

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::atomic<bool> stopped_{false};
};

/// \brief Keeps a link up in its own thread: connect, run the session until the link fails, wait
/// a backoff, connect again. The first failure is logged as an error, repeats as warnings every
/// `log_every` attempts. Thread-safe.
class Reconnector
{
 public:
  struct Callbacks
  {
    /// Opens the link; throws (any cnc_bridge::Error) on failure.
    std::function<void()> connect;
    /// Runs until the link fails (throws) or stop is requested (returns).
    std::function<void()> session;
    /// Told of every state change and failure text (empty when none).
    std::function<void(LinkState, const std::string&)> on_state;
    /// Called after a failure to release the link (close sockets); optional.
    std::function<void()> disconnect;
  };

  Reconnector(std::string name, Callbacks callbacks, Backoff backoff = Backoff());
  ~Reconnector();

  void start();
  /// \brief Stops the loop: wakes the backoff wait; the session must return when its link is
  /// interrupted (the disconnect callback should interrupt it). Joins the thread.
  void stop();
  unsigned reconnects() const { return reconnects_; }
  unsigned failures() const { return failures_; }

 private:
  void run();

  std::string name_;
  Callbacks callbacks_;
  Backoff backoff_;
  StopSignal stop_;
  std::thread thread_;
  std::atomic<unsigned> reconnects_{0};
  std::atomic<unsigned> failures_{0};
};
}  // namespace cnc_bridge
