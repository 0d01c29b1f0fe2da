// The control side of DNC drip-feed and program backup, for sim_haas_serial's `drip` and `punch`
// modes and for the unit tests that run them in-process on a pty. ROS-free.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>

#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace sim
{
/// \brief A control executing a drip-fed program: a finite receive buffer drained at an execution
/// rate, XOFF above a high mark, XON below a low mark. Not thread-safe (one run() at a time).
///
/// The control's UART is modelled (line_cps > 0): it takes characters from the link no faster than
/// the line carries them, so whatever the host has written beyond the line rate stays queued on
/// the host's side (on a pty: in the pty), as it would in the host's kernel and adapter. Every
/// character the control takes after it wrote its XOFF (DC3), until its XON, counts against the
/// host, what the host had queued at that moment included; those beyond `allowance` per XOFF are
/// overruns, which a real Fanuc answers with an alarm. When this process is scheduled late it
/// catches up at the line rate: the characters the line would have carried meanwhile arrived
/// before the XOFF it then sends. Characters that arrive with the buffer full are lost (counted
/// as overflow). Which of these behaviours a manual states (DC1/DC3, the ten characters after DC3)
/// and which are this model's own choices (buffer size, marks, execution rate, one stop bit): the
/// table in test/data/dnc_drip/README.md.
struct DripControlOptions
{
  size_t buffer_size = 1024;    ///< characters the control can hold
  size_t high_mark = 768;       ///< XOFF when the buffer reaches this
  size_t low_mark = 256;        ///< XON when it drains to this
  double execution_cps = 2000;  ///< characters executed (removed from the buffer) per second; 0 = instantly
  /// Characters per second the line carries (baud / bits per character): the UART takes no more.
  /// 0 = no line model, take whatever has arrived (what the host queued then never counts).
  double line_cps = 0;
  size_t allowance = 10;           ///< characters the control takes after its XOFF without alarm
  bool seven_e1 = false;           ///< send DC1/DC3 with the even-parity bit set, mask it on input
  bool stop_at_end = true;         ///< return after the second '%' and its EOB, any XOFF answered
  bool send_dc1_at_start = false;  ///< send DC1 ("reader start") once ready, as a Fanuc in DNC mode does
  /// Run the receiving thread at real-time priority (SCHED_FIFO) when the system allows it, so the
  /// modelled UART keeps up with the line on a loaded machine. Ignored (the normal priority kept)
  /// when not permitted.
  bool realtime = false;
};

struct DripControlStats
{
  uint64_t received = 0;  ///< characters received (leader and DC codes included)
  uint64_t xoff_events = 0;
  uint64_t max_after_xoff = 0;       ///< most characters taken after one XOFF went out, before its XON
  uint64_t xoff_over_allowance = 0;  ///< XOFF events after which more than the allowance came
  uint64_t overruns = 0;             ///< characters beyond the allowance, summed over all XOFFs
  uint64_t overflow = 0;             ///< characters lost to a full buffer
  /// Characters the control took past its high mark before its XOFF went out (on a LineClock:
  /// that had arrived before it went out), summed: its own reaction time (a simulator thread
  /// scheduled late reads a batch at once, or writes its DC3 late), not the host's.
  uint64_t late = 0;
  /// Of the overflow, the characters beyond what the control's own lateness explains, per XOFF
  /// event: the host's share, 0 for a host that honours XOFF within the buffer's headroom.
  uint64_t overflow_beyond_late = 0;
  uint64_t parity_errors = 0;     ///< 7E1: bytes whose bit 7 was set but did not give even parity
  bool program_complete = false;  ///< the second '%' arrived
  bool reset = false;             ///< the operator reset the control (DripControlHooks::reset)

  /// \brief One line for the simulator's exit report.
  std::string summary() const;
};

/// \brief The control's UART: how many characters it may take from the link now. With a line
/// rate, no more than the line has carried since the previous character; after the link ran empty,
/// the next character starts the line again when it arrives. One model can serve several
/// runDripControl() runs (program after program), so that the time the simulator spends between
/// two programs counts as time the line carried characters, as a real UART's would.
class UartModel
{
 public:
  explicit UartModel(double line_cps) : cps_(line_cps) {}
  bool modelled() const { return cps_ > 0; }
  /// Characters the next read may take (>= 1), sleeping until the line has carried one.
  size_t allowed(size_t limit)
  {
    if (!modelled() || idle_)
    {
      return idle_ && modelled() ? 1 : limit;  // waiting for the line to start: one character
    }
    accrue();
    if (credit_ < 1)
    {
      std::this_thread::sleep_for(std::chrono::duration<double>((1 - credit_) / cps_));
      accrue();
    }
    return static_cast<size_t>(std::min<double>(static_cast<double>(limit), std::max(1.0, std::floor(credit_))));
  }
  /// How long the read may wait: only when the line is empty (for the next character to arrive).
  Milliseconds timeout() const { return !modelled() || idle_ ? Milliseconds(1) : Milliseconds(0); }
  /// The read returned \p got of the \p wanted characters.
  void took(size_t got, size_t wanted)
  {
    if (!modelled())
    {
      return;
    }
    if (idle_)
    {
      if (got > 0)
      {
        idle_ = false;  // it arrived now: the line carries the next one from here
        credit_ = 0;
        last_ = std::chrono::steady_clock::now();
      }
      return;
    }
    credit_ -= static_cast<double>(got);
    if (got < wanted)
    {
      idle_ = true;  // the host had nothing more queued: the line went quiet
      credit_ = 0;
    }
  }

 private:
  void accrue()
  {
    const auto now = std::chrono::steady_clock::now();
    credit_ += std::chrono::duration<double>(now - last_).count() * cps_;
    last_ = now;
  }
  double cps_;
  bool idle_ = true;
  double credit_ = 0;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};
/// \brief What the control does with what it received, for a log of its execution, and the
/// operator's RESET. Every member may be empty.
///
/// A block executes when its end of block (LF) is executed, so a block whose end has not arrived
/// never runs; its text is given without the end of block, tape-feed NULs and DC codes. When the
/// buffer runs empty in the middle of a program (the last block executed is not a '%'), the control
/// waits for data, as a DNC control does when its host stops sending: it does not run on.
struct DripControlHooks
{
  std::function<void(const std::string& block)> executed;  ///< a block, once executed
  std::function<void()> waiting_for_data;                  ///< the buffer ran empty mid-program (once per time)
  /// Polled while the control runs: true = the operator pressed RESET. The run ends at once, the
  /// program abandoned: what is buffered and the block being read are dropped, and the next run
  /// takes the next '%' as the start of a program (a control that starved needs a reset before a
  /// restart, or it would read the restart's '%' as the end of the program it was running).
  std::function<bool()> reset;
};

/// \brief A link that knows when its characters were on the wire (sim::SimulatedLine). On such a
/// link the control judges its XOFF by the line's clock: a character that had fully arrived
/// before the DC3 started out counts as the control's own lateness (its thread ran late between
/// the read and the write), not against the host, however the two threads were scheduled.
class LineClock
{
 public:
  using TimePoint = std::chrono::steady_clock::time_point;
  virtual ~LineClock() = default;
  /// When character \p index of the last read finished arriving.
  virtual TimePoint lastReadCarriedAt(size_t index) const = 0;
  /// When the last character written starts on the wire.
  virtual TimePoint lastWriteStartsAt() const = 0;
};

/// \brief Runs the control until the program ends (stop_at_end), \p stop is signalled, the operator
/// resets it (\p hooks), or the link fails. \p sink receives every received character (parity
/// masked) in order. \p line: the UART model to use (kept across runs by the caller); nullptr = a
/// new one of options.line_cps. At the end of a program the blocks still buffered are executed at
/// once (the next run starts with an empty buffer). On a link that is also a LineClock, characters
/// count as after an XOFF by when they were on the wire.
DripControlStats runDripControl(Transport& link, const DripControlOptions& options, StopSignal& stop,
                                const std::function<void(const uint8_t*, size_t)>& sink, UartModel* line = nullptr,
                                const DripControlHooks& hooks = {});

/// \brief A control punching a program (backup): options of the `punch` mode.
struct PunchOptions
{
  std::string eob = "\r\n";   ///< Haas punches CR LF
  size_t leader_length = 16;  ///< NULs before and after (tape feed)
  bool dc_codes = true;       ///< DC2 before, DC4 after
  bool end_percent = true;    ///< false: no closing '%' (the host must end on silence)
  bool seven_e1 = false;      ///< set the even-parity bit on every byte
  bool wait_for_dc1 = true;   ///< punch when the host sends DC1 (ready); false: at once
};

/// \brief Punches the program in \p path (adding '%' framing if the file lacks it) to \p link.
/// \returns the number of bytes sent. \throws Error on a link or file error.
uint64_t punchProgram(Transport& link, const std::string& path, const PunchOptions& options, StopSignal& stop);
}  // namespace sim
}  // namespace cnc_bridge
