// The 1 ms setpoint sender of the '@'-protocol node. The original controller runs a Xenomai loop that
// takes one setpoint per 1 ms time step from a pipe; the host must keep that pipe fed. This file
// holds the dedicated thread that writes every message of the command socket: setpoints on an
// absolute-time schedule, and commands queued by ROS callbacks, which only ever touch a short
// queue and never the socket, so no callback can delay a setpoint.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <variant>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/sequencer.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief Intervals between consecutive setpoints, 1 us buckets up to 20 ms. One writer (the
/// sender thread), any number of readers (relaxed atomics: a reader may see a sample half-counted).
class IntervalHistogram
{
 public:
  static constexpr size_t kBuckets = 20000;  // us
  void record(int64_t nanoseconds);
  void reset();
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }
  /// \returns the interval below which \p fraction of the samples lie, in seconds (0 if empty).
  double percentile(double fraction) const;
  double max() const { return static_cast<double>(max_ns_.load(std::memory_order_relaxed)) * 1e-9; }
  double min() const;

 private:
  std::array<std::atomic<uint32_t>, kBuckets + 1> buckets_{};
  std::atomic<uint64_t> count_{0};
  std::atomic<int64_t> max_ns_{0};
};

/// \brief What one `~follow_path` goal sends: M1@, P@, T@, S@, the setpoints, #@, M0@ (at_protocol.md, steps).
struct Operation
{
  bool coolant = false;
  std::optional<ToolChange> tool;  ///< sent after P@ (step 7)
  std::optional<int> spindle;      ///< 0..255, sent after the tool change (step 8)
  std::shared_ptr<const Trajectory> trajectory;
};

/// \brief A running operation as seen from other threads. Thread-safe.
class Job
{
 public:
  enum class State
  {
    kRunning,
    kSucceeded,  ///< every setpoint sent, #@ and M0@ sent
    kCancelled,  ///< cancel() honoured: decelerated to a stop along the path
    kAborted,    ///< abort(): streaming stopped at once (emergency stop)
    kFailed,     ///< the command link failed
  };
  static const char* toString(State state);

  /// \brief Decelerate to a stop along the path, then end the operation. Never blocks.
  void cancel() { cancel_requested_ = true; }
  /// \brief Stop streaming at once (the controller is in emergency stop and no longer follows).
  void abort(const std::string& reason);

  /// \returns true once the job has ended (then state() and message() are final).
  bool waitFor(Milliseconds timeout) const;
  bool done() const { return state() != State::kRunning; }
  State state() const { return state_.load(); }
  std::string message() const;
  uint64_t sent() const { return sent_.load(std::memory_order_relaxed); }
  uint64_t total() const { return total_.load(std::memory_order_relaxed); }
  /// The last setpoint sent (axes read one by one: they may come from consecutive steps).
  Setpoint current() const;
  /// Pulses along the operation's path of the last setpoint (see TrajectoryStream::distance): once
  /// the job was cancelled, where along the path it came to rest.
  double distance() const { return distance_.load(std::memory_order_relaxed); }
  const Operation& operation() const { return operation_; }
  /// When the last setpoint sent was written (the epoch before the first): a report that arrives
  /// later can tell where the axes went after it (see EndConfirmation).
  std::chrono::steady_clock::time_point lastSetpointAt() const
  {
    return std::chrono::steady_clock::time_point(std::chrono::steady_clock::duration(last_setpoint_at_.load()));
  }

 private:
  friend class SetpointSender;
  explicit Job(Operation operation) : operation_(std::move(operation)) {}
  void finish(State state, const std::string& message);
  void publish(const Setpoint& setpoint, uint64_t sent, uint64_t total, double distance);

  Operation operation_;
  std::atomic<bool> cancel_requested_{false};
  std::atomic<bool> abort_requested_{false};
  std::atomic<State> state_{State::kRunning};
  std::atomic<uint64_t> sent_{0};
  std::atomic<uint64_t> total_{0};
  std::atomic<double> distance_{0.0};
  std::atomic<std::chrono::steady_clock::rep> last_setpoint_at_{0};  ///< steady_clock ticks
  std::array<std::atomic<int32_t>, 3> position_{};
  std::array<std::atomic<int>, 3> feed_{};
  mutable std::mutex mutex_;
  mutable std::condition_variable done_cv_;
  std::string message_;
  std::string abort_reason_;
};

/// \brief Owns the command socket's writes: one thread, absolute-time 1 ms schedule. Thread-safe.
///
/// Timing: setpoint k of a job is due at t0 + k * period (CLOCK_MONOTONIC, clock_nanosleep with
/// TIMER_ABSTIME), t0 being when the job's prologue was written. A setpoint written more than one
/// period after its due time is an underrun: counted, and the schedule is kept (the following
/// setpoints go out back to back until it has caught up) so the path keeps its timing and no
/// setpoint is skipped, which would make the axes jump.
class SetpointSender
{
 public:
  struct Options
  {
    double period = 0.001;  ///< s
    /// SCHED_FIFO priority of the sender thread; 0 leaves the normal scheduler (needs CAP_SYS_NICE).
    /// With a priority the process also locks its memory and keeps the CPUs out of idle states
    /// (/dev/cpu_dma_latency = 0) while the sender lives, as a real-time latency test does.
    int realtime_priority = 0;
    /// Longest a write may block before the link counts as failed (a controller that stopped reading).
    Milliseconds write_timeout{200};
    /// Called from the sender thread when a write fails; the link owner reconnects.
    std::function<void(const std::string&)> on_link_error;
  };

  struct Stats
  {
    uint64_t setpoints = 0;
    uint64_t underruns = 0;
    /// Times the schedule fell more than one period behind (one stall makes several underruns:
    /// the setpoints that were due meanwhile). Compare with a latency test's late wake-ups.
    uint64_t stalls = 0;
    uint64_t commands = 0;
    double max_lateness = 0.0;   ///< s, worst delay of a setpoint behind its due time
    double mean_lateness = 0.0;  ///< s
    double interval_p50 = 0.0, interval_p99 = 0.0, interval_max = 0.0, interval_min = 0.0;  ///< s
  };

  explicit SetpointSender(Options options);
  ~SetpointSender();
  SetpointSender(const SetpointSender&) = delete;
  SetpointSender& operator=(const SetpointSender&) = delete;

  /// \brief The command link to write to (nullptr when down). Thread-safe; a new link resets the
  /// sequencing state (a reconnected controller starts over).
  void setLink(std::shared_ptr<Transport> link);
  bool linkUp() const;

  /// \brief Queues one command behind those already queued.
  /// \returns a future that becomes ready when the command is written, or holds the LinkError.
  /// \throws ProtocolError if the sequencing rules refuse it now (jog while machining, ...).
  std::future<void> send(const Command& command);

  /// \brief Starts an operation: M1@, P@, optional T@ and S@, setpoints every period, #@, M0@.
  /// \throws ProtocolError if machining is already in progress; LinkError if the link is down.
  std::shared_ptr<Job> start(Operation operation);

  /// \brief Aborts the running job, if any (see Job::abort).
  void abortRunning(const std::string& reason);

  /// \brief A copy of the sequencing state (phase, spindle, coolant, tool, mode).
  Sequencer sequencer() const;
  Stats stats() const;
  /// \brief Clears the statistics (the benchmark measures one run).
  void resetStats();

 private:
  struct Queued
  {
    Command command;
    std::shared_ptr<std::promise<void>> done;
  };
  using Item = std::variant<Queued, std::shared_ptr<Job>>;

  void run();
  void runJob(const std::shared_ptr<Job>& job);
  // The steps of runJob: the commands before the setpoints, the setpoints until the path ends or
  // the job is cancelled or aborted (false: the link failed and finished the job), the timing of
  // one setpoint written, and the sequencer and job brought to the end.
  void writePrologue(const Operation& operation);
  bool streamJob(Job& job, TrajectoryStream& stream, Job::State& outcome, std::string& message);
  void recordWrite(int64_t due, int64_t period_ns, bool& behind);
  void endJob(Job& job, Job::State state, const std::string& message);
  /// Writes queued commands that are ready; \p wait_lock false: give up if the lock is busy.
  bool writeQueuedCommands(bool wait_lock);
  void write(const std::string& bytes);
  void linkFailed(const std::string& why);
  std::shared_ptr<Transport> link() const;

  Options options_;
  mutable std::mutex mutex_;  // guards queue_, sequencer_, running_, link_
  std::condition_variable cv_;
  std::deque<Item> queue_;
  Sequencer sequencer_;
  std::shared_ptr<Job> running_;
  std::shared_ptr<Transport> link_;
  std::atomic<bool> stopping_{false};
  std::string buffer_;

  IntervalHistogram intervals_;
  std::atomic<uint64_t> setpoints_{0};
  std::atomic<uint64_t> underruns_{0};
  std::atomic<uint64_t> stalls_{0};
  std::atomic<uint64_t> commands_{0};
  std::atomic<int64_t> max_late_ns_{0};
  std::atomic<int64_t> sum_late_ns_{0};
  int64_t last_write_ns_ = 0;
  int cpu_latency_fd_ = -1;  ///< /dev/cpu_dma_latency held open in real-time mode

  std::thread thread_;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
