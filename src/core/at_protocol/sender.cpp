// The 1 ms sender thread of the '@'-protocol node (see sender.h for the timing rules).
#include "cnc_bridge/at_protocol/sender.h"

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
int64_t monotonicNs()
{
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<int64_t>(now.tv_sec) * 1000000000LL + now.tv_nsec;
}

/// Sleeps until an absolute CLOCK_MONOTONIC time; an early wake by a signal sleeps again.
void sleepUntilNs(int64_t deadline)
{
  timespec when{};
  when.tv_sec = static_cast<time_t>(deadline / 1000000000LL);
  when.tv_nsec = static_cast<long>(deadline % 1000000000LL);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &when, nullptr) == EINTR)
  {
  }
}

/// What a real-time latency test (cyclictest) does before it measures: lock the process's memory,
/// so the loop never waits for a page fault, and ask the kernel to keep the CPUs out of idle states
/// slower to leave than zero microseconds (on a virtual machine: poll rather than halt the vCPU,
/// which the host may not resume for milliseconds). \returns the descriptor that holds the request.
int prepareForRealtime(std::vector<std::string>& refused)
{
  if (::mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
  {
    refused.push_back(std::string("memory not locked (mlockall: ") + std::strerror(errno) + ")");
  }
  const int fd = ::open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  const int32_t no_latency = 0;
  if (fd < 0 || ::write(fd, &no_latency, sizeof no_latency) != static_cast<ssize_t>(sizeof no_latency))
  {
    refused.push_back(std::string("CPU idle latency not limited (/dev/cpu_dma_latency: ") + std::strerror(errno) + ")");
    if (fd >= 0)
    {
      ::close(fd);
    }
    return -1;
  }
  return fd;
}

void atomicMax(std::atomic<int64_t>& target, int64_t value)
{
  int64_t seen = target.load(std::memory_order_relaxed);
  while (value > seen && !target.compare_exchange_weak(seen, value, std::memory_order_relaxed))
  {
  }
}
}  // namespace

// ---- IntervalHistogram -------------------------------------------------------------------------

void IntervalHistogram::record(int64_t nanoseconds)
{
  const int64_t us = std::max<int64_t>(0, nanoseconds / 1000);
  const size_t bucket = static_cast<size_t>(std::min<int64_t>(us, kBuckets));
  buckets_[bucket].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  atomicMax(max_ns_, nanoseconds);
}

void IntervalHistogram::reset()
{
  for (auto& bucket : buckets_)
  {
    bucket.store(0, std::memory_order_relaxed);
  }
  count_.store(0, std::memory_order_relaxed);
  max_ns_.store(0, std::memory_order_relaxed);
}

double IntervalHistogram::percentile(double fraction) const
{
  const uint64_t total = count();
  if (total == 0)
  {
    return 0.0;
  }
  const auto wanted = static_cast<uint64_t>(std::ceil(fraction * static_cast<double>(total)));
  uint64_t seen = 0;
  for (size_t i = 0; i <= kBuckets; ++i)
  {
    seen += buckets_[i].load(std::memory_order_relaxed);
    if (seen >= std::max<uint64_t>(wanted, 1))
    {
      return (static_cast<double>(i) + 0.5) * 1e-6;  // bucket centre
    }
  }
  return max();
}

double IntervalHistogram::min() const
{
  for (size_t i = 0; i <= kBuckets; ++i)
  {
    if (buckets_[i].load(std::memory_order_relaxed) > 0)
    {
      return static_cast<double>(i) * 1e-6;
    }
  }
  return 0.0;
}

// ---- Job ---------------------------------------------------------------------------------------

const char* Job::toString(State state)
{
  switch (state)
  {
    case State::kRunning:
      return "running";
    case State::kSucceeded:
      return "succeeded";
    case State::kCancelled:
      return "cancelled";
    case State::kAborted:
      return "aborted";
    case State::kFailed:
      return "failed";
  }
  return "?";
}

void Job::abort(const std::string& reason)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (abort_reason_.empty())
    {
      abort_reason_ = reason;
    }
  }
  abort_requested_ = true;
}

bool Job::waitFor(Milliseconds timeout) const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return done_cv_.wait_for(lock, timeout, [this] { return state_.load() != State::kRunning; });
}

std::string Job::message() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return message_;
}

Setpoint Job::current() const
{
  Setpoint setpoint;
  for (int i = 0; i < 3; ++i)
  {
    setpoint.position[i] = position_[i].load(std::memory_order_relaxed);
    setpoint.feed[i] = feed_[i].load(std::memory_order_relaxed);
  }
  return setpoint;
}

void Job::finish(State state, const std::string& message)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    message_ = message;
    state_ = state;
  }
  done_cv_.notify_all();
}

void Job::publish(const Setpoint& setpoint, uint64_t sent, uint64_t total, double distance)
{
  distance_.store(distance, std::memory_order_relaxed);
  for (int i = 0; i < 3; ++i)
  {
    position_[i].store(setpoint.position[i], std::memory_order_relaxed);
    feed_[i].store(setpoint.feed[i], std::memory_order_relaxed);
  }
  total_.store(total, std::memory_order_relaxed);
  // Published after the write: a report that arrives later came after the controller had it.
  last_setpoint_at_.store(std::chrono::steady_clock::now().time_since_epoch().count(), std::memory_order_relaxed);
  sent_.store(sent, std::memory_order_release);
}

// ---- SetpointSender ----------------------------------------------------------------------------

SetpointSender::SetpointSender(Options options) : options_(std::move(options))
{
  if (!(options_.period > 0.0))
  {
    throw ConfigError("setpoint sender: the period must be positive");
  }
  buffer_.reserve(4096);
  std::vector<std::string> refused;
  if (options_.realtime_priority > 0)
  {
    cpu_latency_fd_ = prepareForRealtime(refused);
  }
  thread_ = std::thread([this] { run(); });
  if (options_.realtime_priority > 0)
  {
    sched_param param{};
    param.sched_priority = options_.realtime_priority;
    const int error = pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &param);
    if (error != 0)
    {
      refused.insert(refused.begin(), "SCHED_FIFO priority " + std::to_string(options_.realtime_priority) +
                                          " not granted (" + std::strerror(error) +
                                          "): streaming with the normal scheduler");
    }
  }
  if (!refused.empty())
  {
    // One warning that says what was refused and what allows it (capabilities(7), limits.conf(5)).
    std::string what;
    for (const auto& r : refused)
    {
      what += (what.empty() ? "" : "; ") + r;
    }
    CNC_LOG_WARN("setpoint sender: real-time mode not granted: "
                 << what << ". To allow it, give the program CAP_SYS_NICE and CAP_IPC_LOCK (setcap "
                 << "cap_sys_nice,cap_ipc_lock+ep <node binary>), or add to /etc/security/limits.conf the lines "
                 << "'<user> - rtprio " << options_.realtime_priority << "' and '<user> - memlock unlimited' "
                 << "(the CPU idle latency request needs write access to /dev/cpu_dma_latency); a setpoint can be "
                 << "late on a loaded machine");
  }
}

SetpointSender::~SetpointSender()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    if (running_)
    {
      running_->abort("the node is shutting down");
    }
  }
  cv_.notify_all();
  if (auto current = link())
  {
    current->interrupt();
  }
  thread_.join();
  if (cpu_latency_fd_ >= 0)
  {
    ::close(cpu_latency_fd_);  // the CPUs may idle deeply again
  }
}

std::shared_ptr<Transport> SetpointSender::link() const
{
  return std::atomic_load(&link_);
}

void SetpointSender::setLink(std::shared_ptr<Transport> link)
{
  std::shared_ptr<Job> running;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::atomic_store(&link_, std::move(link));
    sequencer_.reset();
    running = running_;
  }
  if (running && !linkUp())
  {
    running->abort("the command link went down");
  }
  cv_.notify_all();
}

bool SetpointSender::linkUp() const
{
  return link() != nullptr;
}

std::future<void> SetpointSender::send(const Command& command)
{
  if (std::holds_alternative<Setpoint>(command))
  {
    throw ProtocolError("setpoints are sent by a follow_path operation, not one by one");
  }
  encode(command);  // range check now, in the caller's thread
  auto done = std::make_shared<std::promise<void>>();
  auto future = done->get_future();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!link())
    {
      throw LinkError("the command link to the controller is down");
    }
    sequencer_.apply(command);
    queue_.emplace_back(Queued{command, std::move(done)});
  }
  cv_.notify_all();
  return future;
}

std::shared_ptr<Job> SetpointSender::start(Operation operation)
{
  if (!operation.trajectory)
  {
    throw ConfigError("setpoint sender: an operation needs a trajectory");
  }
  if (operation.spindle)
  {
    encode(Spindle{*operation.spindle});
  }
  if (operation.tool)
  {
    encode(*operation.tool);
  }
  std::shared_ptr<Job> job(new Job(std::move(operation)));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!link())
    {
      throw LinkError("the command link to the controller is down");
    }
    if (running_)
    {
      throw ProtocolError("an operation is already running");
    }
    // Check the whole prologue on a copy, so a refusal leaves the state as it was.
    Sequencer check = sequencer_;
    check.apply(Machining{true});
    check.apply(StartOperation{job->operation().coolant});
    sequencer_ = check;
    running_ = job;
    queue_.emplace_back(job);
  }
  cv_.notify_all();
  return job;
}

void SetpointSender::abortRunning(const std::string& reason)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (running_)
  {
    running_->abort(reason);
  }
}

Sequencer SetpointSender::sequencer() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return sequencer_;
}

SetpointSender::Stats SetpointSender::stats() const
{
  Stats stats;
  stats.setpoints = setpoints_.load(std::memory_order_relaxed);
  stats.underruns = underruns_.load(std::memory_order_relaxed);
  stats.stalls = stalls_.load(std::memory_order_relaxed);
  stats.commands = commands_.load(std::memory_order_relaxed);
  stats.max_lateness = static_cast<double>(max_late_ns_.load(std::memory_order_relaxed)) * 1e-9;
  stats.mean_lateness = stats.setpoints > 0 ? static_cast<double>(sum_late_ns_.load(std::memory_order_relaxed)) * 1e-9 /
                                                  static_cast<double>(stats.setpoints)
                                            : 0.0;
  stats.interval_p50 = intervals_.percentile(0.5);
  stats.interval_p99 = intervals_.percentile(0.99);
  stats.interval_max = intervals_.max();
  stats.interval_min = intervals_.min();
  return stats;
}

void SetpointSender::resetStats()
{
  intervals_.reset();
  setpoints_ = 0;
  underruns_ = 0;
  stalls_ = 0;
  max_late_ns_ = 0;
  sum_late_ns_ = 0;
}

void SetpointSender::write(const std::string& bytes)
{
  auto current = link();
  if (!current)
  {
    throw LinkError("the command link to the controller is down");
  }
  current->write(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), options_.write_timeout);
}

void SetpointSender::linkFailed(const std::string& why)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::atomic_store(&link_, std::shared_ptr<Transport>());
    sequencer_.reset();
    // Everything still queued was never sent.
    for (auto& item : queue_)
    {
      if (auto* queued = std::get_if<Queued>(&item))
      {
        queued->done->set_exception(std::make_exception_ptr(LinkError(why)));
      }
      else
      {
        std::get<std::shared_ptr<Job>>(item)->finish(Job::State::kFailed, why);
      }
    }
    queue_.clear();
    if (running_ && !running_->done())
    {
      running_->finish(Job::State::kFailed, why);
    }
    running_.reset();
  }
  if (options_.on_link_error)
  {
    options_.on_link_error(why);
  }
}

bool SetpointSender::writeQueuedCommands(bool wait_lock)
{
  // Collect under the lock, write outside it: a slow socket never holds up a ROS callback.
  std::deque<Queued> ready;
  std::shared_ptr<Job> job;
  {
    std::unique_lock<std::mutex> lock(mutex_, std::defer_lock);
    if (wait_lock)
    {
      lock.lock();
    }
    else if (!lock.try_lock())
    {
      return false;  // a callback holds it for a moment: next period
    }
    while (!queue_.empty())
    {
      if (auto* queued = std::get_if<Queued>(&queue_.front()))
      {
        ready.push_back(std::move(*queued));
        queue_.pop_front();
        continue;
      }
      if (wait_lock)  // jobs start only from the idle loop
      {
        job = std::get<std::shared_ptr<Job>>(queue_.front());
        queue_.pop_front();
      }
      break;
    }
  }
  for (size_t i = 0; i < ready.size(); ++i)
  {
    try
    {
      write(encode(ready[i].command));
      ++commands_;
      ready[i].done->set_value();
    }
    catch (const Error& e)
    {
      for (size_t j = i; j < ready.size(); ++j)
      {
        ready[j].done->set_exception(std::make_exception_ptr(LinkError(e.what())));
      }
      if (job)
      {
        job->finish(Job::State::kFailed, e.what());
      }
      linkFailed(e.what());
      return true;
    }
  }
  if (job)
  {
    runJob(job);
  }
  return true;
}

void SetpointSender::run()
{
  while (!stopping_)
  {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait_for(lock, std::chrono::milliseconds(100), [this] { return stopping_ || !queue_.empty(); });
      if (stopping_)
      {
        break;
      }
    }
    writeQueuedCommands(true);
  }
  // Shutting down: whatever is still queued will not be sent.
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& item : queue_)
  {
    if (auto* queued = std::get_if<Queued>(&item))
    {
      queued->done->set_exception(std::make_exception_ptr(CancelledError("the node is shutting down")));
    }
    else
    {
      std::get<std::shared_ptr<Job>>(item)->finish(Job::State::kAborted, "the node is shutting down");
    }
  }
  queue_.clear();
}

void SetpointSender::runJob(const std::shared_ptr<Job>& job)
{
  const Operation& operation = job->operation();
  TrajectoryStream stream(*operation.trajectory);
  try
  {
    writePrologue(operation);
    Job::State outcome = Job::State::kSucceeded;
    std::string message = "path complete";
    if (!streamJob(*job, stream, outcome, message))
    {
      return;  // the commands' write failed and finished the job
    }
    // Epilogue: #@ ends the operation (coolant off, step 16), M0@ the machining (spindle 0).
    write(encode(EndOperation{}) + encode(Machining{false}));
    commands_ += 2;
    endJob(*job, outcome, message);
  }
  catch (const Error& e)
  {
    std::string why = e.what();
    if (job->abort_requested_)
    {
      std::lock_guard<std::mutex> lock(job->mutex_);
      why = job->abort_reason_ + " (" + why + ")";
    }
    endJob(*job, Job::State::kFailed, why);
    linkFailed(why);
  }
}

void SetpointSender::writePrologue(const Operation& operation)
{
  // Prologue in the order of at_protocol.md#sequence-of-one-machining: M1@ (1), P@ (5), tool (7), spindle (8).
  std::string prologue = encode(Machining{true}) + encode(StartOperation{operation.coolant});
  if (operation.tool)
  {
    prologue += encode(*operation.tool);
  }
  if (operation.spindle)
  {
    prologue += encode(Spindle{*operation.spindle});
  }
  write(prologue);
  commands_ += 2 + (operation.tool ? 1 : 0) + (operation.spindle ? 1 : 0);
  std::lock_guard<std::mutex> lock(mutex_);
  if (operation.tool)
  {
    sequencer_.apply(*operation.tool);
  }
  if (operation.spindle)
  {
    sequencer_.apply(Spindle{*operation.spindle});
  }
}

bool SetpointSender::streamJob(Job& job, TrajectoryStream& stream, Job::State& outcome, std::string& message)
{
  const auto period_ns = static_cast<int64_t>(std::llround(options_.period * 1e9));
  int64_t due = monotonicNs() + period_ns;
  bool behind = false;  // the previous setpoint was an underrun: this one belongs to the same stall
  last_write_ns_ = 0;
  Setpoint setpoint;
  for (;;)
  {
    sleepUntilNs(due);
    if (job.abort_requested_)
    {
      outcome = Job::State::kAborted;
      std::lock_guard<std::mutex> lock(job.mutex_);
      message = job.abort_reason_;
      return true;
    }
    if (job.cancel_requested_ && !stream.stopping())
    {
      stream.stop();
    }
    if (!stream.next(setpoint))
    {
      if (stream.stopping())
      {
        outcome = Job::State::kCancelled;
        message = "cancelled: decelerated to a stop";
      }
      return true;
    }
    writeQueuedCommands(false);  // e.g. a spindle change during the operation
    if (!linkUp())
    {
      return false;
    }
    buffer_.clear();
    appendSetpoint(setpoint, buffer_);
    write(buffer_);
    recordWrite(due, period_ns, behind);
    job.publish(setpoint, stream.sent(), stream.total(), stream.distance());
    due += period_ns;
  }
}

void SetpointSender::recordWrite(int64_t due, int64_t period_ns, bool& behind)
{
  const int64_t now = monotonicNs();
  const int64_t late = now - due;
  const bool underrun = late > period_ns;
  if (underrun)
  {
    underruns_.fetch_add(1, std::memory_order_relaxed);
    if (!behind)
    {
      stalls_.fetch_add(1, std::memory_order_relaxed);
    }
  }
  behind = underrun;
  atomicMax(max_late_ns_, late);
  sum_late_ns_.fetch_add(std::max<int64_t>(late, 0), std::memory_order_relaxed);
  if (last_write_ns_ != 0)
  {
    intervals_.record(now - last_write_ns_);
  }
  last_write_ns_ = now;
  setpoints_.fetch_add(1, std::memory_order_relaxed);
}

void SetpointSender::endJob(Job& job, Job::State state, const std::string& message)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // The epilogue was written (or the link is gone and the controller starts over anyway).
    if (sequencer_.phase() == Phase::kOperation)
    {
      sequencer_.apply(EndOperation{});
    }
    if (sequencer_.phase() == Phase::kMachining)
    {
      sequencer_.apply(Machining{false});
    }
    running_.reset();
  }
  job.finish(state, message);
}
}  // namespace at_protocol
}  // namespace cnc_bridge
