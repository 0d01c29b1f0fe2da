// The simulated control of a drip-feed: buffer, execution rate, XON/XOFF marks, overrun counting.
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <sstream>
#include <thread>
#include <vector>

#include "cnc_bridge/dnc/dnc_codes.h"
#include "dnc_sim.h"

namespace cnc_bridge
{
namespace sim
{
std::string DripControlStats::summary() const
{
  std::ostringstream out;
  out << "received " << received << " characters, xoff " << xoff_events << ", max after xoff " << max_after_xoff
      << ", xoff over allowance " << xoff_over_allowance << ", overruns " << overruns << ", overflow " << overflow
      << " (beyond the control's own lateness " << overflow_beyond_late << ", late " << late << ")"
      << ", parity errors " << parity_errors << ", program " << (program_complete ? "complete" : "incomplete")
      << (reset ? ", reset" : "");
  return out.str();
}

namespace
{
using Clock = std::chrono::steady_clock;

/// The characters in the control's buffer, in order, and the block the control reads from them
/// (DripControlHooks): executing a character moves it into the block; its end of block runs it.
class Execution
{
 public:
  explicit Execution(const DripControlHooks& hooks) : hooks_(hooks) {}

  void buffered(uint8_t c)
  {
    pending_.push_back(c);
    waiting_ = false;
  }

  void execute(size_t count)
  {
    for (size_t i = 0; i < count && !pending_.empty(); ++i)
    {
      read(pending_.front());
      pending_.pop_front();
    }
  }

  void executeAll() { execute(pending_.size()); }

  /// Reports, once, a buffer run empty in the middle of a program.
  void checkStarved()
  {
    if (pending_.empty() && inProgram() && !waiting_)
    {
      waiting_ = true;
      if (hooks_.waiting_for_data)
      {
        hooks_.waiting_for_data();
      }
    }
  }

 private:
  void read(uint8_t c)
  {
    if (c == '\n')
    {
      if (!block_.empty())
      {
        last_ = block_;
        block_.clear();
        if (hooks_.executed)
        {
          hooks_.executed(last_);
        }
      }
    }
    else if (c >= 0x20 && c < 0x7f)  // not CR, tape-feed NULs or DC codes
    {
      block_.push_back(static_cast<char>(c));
    }
  }

  bool inProgram() const { return !last_.empty() && last_ != "%"; }

  const DripControlHooks& hooks_;
  std::deque<uint8_t> pending_;
  std::string block_;  // read so far, its end of block not yet
  std::string last_;   // the block executed last
  bool waiting_ = false;
};

/// One drip-feed session of the control: the buffer accounting between reads, the XOFF/XON
/// events and their statistics, and the end of the program.
class DripSession
{
 public:
  DripSession(Transport& link, const DripControlOptions& options,
              const std::function<void(const uint8_t*, size_t)>& sink, UartModel& uart, const DripControlHooks& hooks)
      : link_(link),
        line_clock_(dynamic_cast<const LineClock*>(&link)),
        options_(options),
        sink_(sink),
        uart_(uart),
        hooks_(hooks),
        execution_(hooks)
  {
    masked_.reserve(sizeof(buffer_));
  }

  DripControlStats run(StopSignal& stop)
  {
    while (!stop.stopped())
    {
      if (hooks_.reset && hooks_.reset())
      {
        stats_.reset = true;
        break;
      }
      const size_t wanted = uart_.allowed(sizeof(buffer_));
      const size_t n = link_.read(buffer_, wanted, uart_.timeout());
      uart_.took(n, wanted);
      const auto now = Clock::now();
      executeDue(now);
      take(buffer_, n);
      execution_.checkStarved();
      if (xoff_ && buffered_ <= options_.low_mark)
      {
        closeXoffEvent();
        link_.writeByte(code(dnc::kDc1));
      }
      if (programEnded(now))
      {
        break;
      }
    }
    if (xoff_)
    {
      closeXoffEvent();
    }
    if (stats_.program_complete)
    {
      execution_.executeAll();
    }
    return stats_;
  }

 private:
  uint8_t code(uint8_t c) const { return options_.seven_e1 ? dnc::withEvenParity(c) : c; }

  /// Executes what the control could have executed since the last read, at its execution rate.
  void executeDue(Clock::time_point now)
  {
    if (options_.execution_cps <= 0)
    {
      execution_.executeAll();
      buffered_ = 0;
    }
    else
    {
      credit_ += std::chrono::duration<double>(now - last_).count() * options_.execution_cps;
      const auto executed = static_cast<size_t>(std::min<double>(static_cast<double>(buffered_), std::floor(credit_)));
      buffered_ -= executed;
      execution_.execute(executed);
      credit_ -= static_cast<double>(executed);
      if (buffered_ == 0)
      {
        credit_ = std::min(credit_, 1.0);  // an idle control does not save up execution time
      }
    }
    last_ = now;
  }

  // Takes what one read returned into the buffer. Every character counts against the host if
  // the XOFF went out before the read; the XOFF is written after the batch that crossed the mark
  // (its characters were on the line before it).
  void take(const uint8_t* data, size_t n)
  {
    masked_.clear();
    bool crossed = false;
    for (size_t i = 0; i < n; ++i)
    {
      uint8_t c = data[i];
      if (options_.seven_e1)
      {
        if ((c & 0x80) != 0 && dnc::withEvenParity(c) != c)
        {
          ++stats_.parity_errors;
        }
        c = dnc::maskParity(c);
      }
      ++stats_.received;
      masked_.push_back(c);
      if (xoff_ && arrivedAfterXoff(i))
      {
        ++after_;
      }
      else if (xoff_ || crossed)
      {
        // A control reacting at the character that crossed would have sent DC3 before this one
        // arrived (or, on a LineClock, this one had arrived before the DC3 went out).
        ++event_late_;
      }
      if (buffered_ >= options_.buffer_size)
      {
        ++stats_.overflow;
        if (xoff_ || crossed)
        {
          ++event_overflow_;
        }
        else
        {
          ++stats_.overflow_beyond_late;  // a buffer smaller than its high mark
        }
      }
      else
      {
        ++buffered_;
        execution_.buffered(c);
      }
      if (c == '%' && ++percents_ == 2)
      {
        stats_.program_complete = true;
        completed_at_ = Clock::now();
      }
      last_char_ = c;
      if (!xoff_ && !crossed && buffered_ >= options_.high_mark)
      {
        crossed = true;
        event_late_ = 0;
        event_overflow_ = 0;
      }
    }
    if (crossed)
    {
      link_.writeByte(code(dnc::kDc3));
      if (line_clock_ != nullptr)
      {
        xoff_on_wire_ = line_clock_->lastWriteStartsAt();
      }
      xoff_ = true;
      after_ = 0;
      ++stats_.xoff_events;
    }
    if (!masked_.empty() && sink_)
    {
      sink_(masked_.data(), masked_.size());
    }
  }

  /// Character \p index of the last read came after the XOFF went out: on a LineClock, had it
  /// fully arrived only once the DC3 started on the wire; elsewhere, it was read after the write.
  bool arrivedAfterXoff(size_t index) const
  {
    return line_clock_ == nullptr || line_clock_->lastReadCarriedAt(index) > xoff_on_wire_;
  }

  void closeXoffEvent()
  {
    stats_.max_after_xoff = std::max(stats_.max_after_xoff, after_);
    if (after_ > options_.allowance)
    {
      stats_.overruns += after_ - options_.allowance;
      ++stats_.xoff_over_allowance;
    }
    stats_.late += event_late_;
    stats_.overflow_beyond_late += event_overflow_ - std::min(event_overflow_, event_late_);
    xoff_ = false;
  }

  // The program ends with the end of block after its closing '%' (LF, or CR alone: then the
  // line falls quiet): take that too, so the next program starts clean. An XOFF still standing
  // is answered first, once the buffer has drained to the low mark: a host that kept the DC3 as
  // the last word from the control would start its next program held, waiting for a DC1 that
  // a control with an empty buffer never has reason to send.
  bool programEnded(Clock::time_point now) const
  {
    return stats_.program_complete && options_.stop_at_end && !xoff_ &&
           (last_char_ == '\n' || now - completed_at_ > std::chrono::milliseconds(50));
  }

  Transport& link_;
  const LineClock* line_clock_;  // nullptr: a link without the wire's times (a pty, a port)
  const DripControlOptions& options_;
  const std::function<void(const uint8_t*, size_t)>& sink_;
  UartModel& uart_;
  const DripControlHooks& hooks_;
  Execution execution_;
  DripControlStats stats_;
  size_t buffered_ = 0;
  double credit_ = 0;  // characters the control could have executed but has not yet
  bool xoff_ = false;
  Clock::time_point xoff_on_wire_;  // when the standing XOFF's DC3 started out (LineClock links)
  uint64_t after_ = 0;
  uint64_t event_late_ = 0;      // this XOFF event: characters taken past the mark before the XOFF
  uint64_t event_overflow_ = 0;  // this XOFF event: characters lost to a full buffer
  unsigned percents_ = 0;
  uint8_t last_char_ = 0;
  Clock::time_point completed_at_;
  Clock::time_point last_ = Clock::now();
  uint8_t buffer_[256];
  std::vector<uint8_t> masked_;
};
}  // namespace

DripControlStats runDripControl(Transport& link, const DripControlOptions& options, StopSignal& stop,
                                const std::function<void(const uint8_t*, size_t)>& sink, UartModel* line,
                                const DripControlHooks& hooks)
{
  if (options.realtime)
  {
    sched_param param{};
    param.sched_priority = 10;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);  // best effort: EPERM keeps the default
  }
  if (options.send_dc1_at_start)
  {
    link.writeByte(options.seven_e1 ? dnc::withEvenParity(dnc::kDc1) : dnc::kDc1);
  }
  UartModel own_uart(options.line_cps);
  DripSession session(link, options, sink, line != nullptr ? *line : own_uart, hooks);
  return session.run(stop);
}
}  // namespace sim
}  // namespace cnc_bridge
