// An RS-232 line in memory, for the drip-feed tests and benchmark: two Transport ends, each
// character taking one character time on the wire in each direction. The host end's kernel
// queue is explicit (pendingOutput(): characters written but not yet carried), and the control
// end receives a character only once the line has carried it, so a simulated control counts
// exactly what a host queued before an XOFF, free of a pty's scheduling delays. Each end also
// tells when its characters were on the wire (sim::LineClock), so the control judges its XOFF by
// the wire's clock, not by when its own thread ran. ROS-free.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/transport/transport.h"
#include "sim/haas_serial/dnc_sim.h"

namespace cnc_bridge
{
namespace sim
{
class SimulatedLine
{
 public:
  /// \param cps characters per second the line carries (baud / bits per character), > 0.
  explicit SimulatedLine(double cps);
  SimulatedLine(const SimulatedLine&) = delete;
  SimulatedLine& operator=(const SimulatedLine&) = delete;

  Transport& host() { return host_; }
  Transport& control() { return control_; }

 private:
  using Clock = std::chrono::steady_clock;
  /// One direction: characters with the time the line has carried each.
  struct Direction
  {
    std::deque<std::pair<uint8_t, Clock::time_point>> queue;
    Clock::time_point line_free;  ///< when the last character written finishes
  };
  /// An end is also a LineClock: a simulated control judges its XOFFs by the wire's times.
  class End : public Transport, public LineClock
  {
   public:
    End(SimulatedLine& line, Direction& out, Direction& in, std::string name)
        : line_(line), out_(out), in_(in), name_(std::move(name))
    {
    }
    size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
    void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override;
    void drain() override;
    size_t pendingOutput() const override;
    void discardInput() override;
    void interrupt() override;
    void close() override { interrupt(); }
    bool isOpen() const override { return true; }
    std::string describe() const override { return name_; }
    TimePoint lastReadCarriedAt(size_t index) const override { return last_read_carried_.at(index); }
    TimePoint lastWriteStartsAt() const override;

   private:
    SimulatedLine& line_;
    Direction& out_;
    Direction& in_;
    std::string name_;
    std::atomic<bool> interrupted_{false};
    std::vector<Clock::time_point> last_read_carried_;  // the reading thread's own
    Clock::time_point last_write_starts_;               // under the line's mutex
  };

  Clock::duration char_time_;
  std::mutex mutex_;
  std::condition_variable changed_;
  Direction to_control_;
  Direction to_host_;
  End host_;
  End control_;
};
}  // namespace sim
}  // namespace cnc_bridge
