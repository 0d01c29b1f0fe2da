// The control side of DNC drip-feed and program backup, for sim_haas_serial's `drip` and `punch`
// modes and for the unit tests that run them in-process on a pty. ROS-free.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

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
/// as overflow).
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
  bool stop_at_end = true;         ///< return after the second '%'
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
  uint64_t parity_errors = 0;        ///< 7E1: bytes whose bit 7 was set but did not give even parity
  bool program_complete = false;     ///< the second '%' arrived

  /// \brief One line for the simulator's exit report.
  std::string summary() const;
};

/// \brief Runs the control until the program ends (stop_at_end), \p stop is signalled, or the link
/// fails. \p sink receives every received character (parity masked) in order.
DripControlStats runDripControl(Transport& link, const DripControlOptions& options, StopSignal& stop,
                                const std::function<void(const uint8_t*, size_t)>& sink);

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
