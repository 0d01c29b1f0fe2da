// DNC drip-feed: the host streams an NC program to a control that executes it while it reads, so
// a program far larger than the control's memory can run (docs/protocols/drip_feed.md). The control
// paces the host with XON/XOFF (or RTS/CTS); the host must stop within 10
// characters of an XOFF, so this sender writes a few characters at a time and looks for DC3
// between writes instead of leaving flow control to the kernel.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/dnc/nc_program.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace dnc
{
/// \brief Who paces the feed.
enum class DripFlow
{
  kNone,     ///< nothing: only the line rate (pace_cps) limits the host
  kXonXoff,  ///< DC3 stops, DC1 resumes, read in user space with the parity bit masked
  kRtsCts    ///< the kernel holds output while CTS is low (open the port with rtscts)
};

/// \brief What to do when the control keeps us held longer than hold_timeout.
enum class HoldTimeoutAction
{
  kFail,   ///< stop the feed with an error (the operator decides)
  kResume  ///< assume the XON was lost on the line and carry on
};

DripFlow parseDripFlow(const std::string& text);  ///< none|xonxoff|rtscts; \throws ConfigError
const char* toString(DripFlow flow);

/// \brief Options of a drip-feed. Defaults suit a Fanuc on ISO code: LF end of block, XON/XOFF.
struct DripOptions
{
  std::string eob = "\n";      ///< bytes sent at each end of block (parseEob())
  bool add_percent = true;     ///< send '%' first and last when the file does not have them
  size_t leader_length = 0;    ///< leader characters before the program (tape feed)
  size_t trailer_length = 0;   ///< the same after it
  uint8_t leader_char = 0x00;  ///< NUL (tape feed holes); some controls want LF or ' '
  bool dc_codes = false;       ///< DC2 before and DC4 after the program (Haas setting 14)
  DripFlow flow = DripFlow::kXonXoff;
  CharacterRules rules;  ///< what the control cannot take, checked before sending
  /// Characters per second the line carries (baud / bits per character). The sender writes no
  /// faster, so that little is queued when XOFF arrives. 0: no pacing, drain after every write.
  double pace_cps = 0;
  size_t chunk = 4;  ///< characters per write (<= xoff_allowance)
  /// Characters the control takes after its XOFF (Fanuc: 10). With pacing, a write goes out when
  /// the line still holds leadCharacters() = xoff_allowance - chunk - 1 characters, so the line
  /// never runs dry while the host wakes up, and what is queued, plus one write, plus the character
  /// time the DC3 itself takes to arrive, never exceeds the allowance.
  size_t xoff_allowance = 10;
  /// SCHED_FIFO priority for the thread running send(), for its length (the normal scheduler is
  /// restored after); 0 = the normal scheduler. A paced sender must wake within a few character
  /// times (0.4 ms at 115200) or the line runs dry; on a loaded machine only a real-time thread
  /// does. Needs CAP_SYS_NICE; without it a warning and the normal scheduler.
  int realtime_priority = 0;
  Milliseconds hold_timeout{0};  ///< held longer than this -> on_hold_timeout; 0 = wait forever
  HoldTimeoutAction on_hold_timeout = HoldTimeoutAction::kFail;
  bool wait_for_dc1 = false;            ///< send nothing until the control asks with DC1 (reader start)
  Milliseconds start_timeout{0};        ///< how long to wait for that DC1; 0 = forever
  Milliseconds progress_interval{100};  ///< progress callback at most this often (and at the end)
  size_t max_line_length = 4096;
  /// Called with the program's head as it is about to be sent (the lines before its first program
  /// block and that block, read from the file the feed sends from), before the first character
  /// goes out; an exception refuses the feed with nothing sent. The protected range is checked
  /// here, so the bytes sent are the bytes checked. The head is read up to kMaxDripHeadBytes.
  std::function<void(const std::string& head)> check_head;
  /// Optional flag another thread sets to cancel (a ROS action preempt); cancel() works as well.
  const std::atomic<bool>* cancel = nullptr;

  /// \throws ConfigError for an empty EOB, a chunk of 0 or above the allowance, a negative rate.
  void validate() const;
};

/// \brief The most a program's head (DripOptions::check_head) may hold: a file with more than this
/// before its first program block is refused.
constexpr size_t kMaxDripHeadBytes = size_t{1024} * 1024;

/// \brief Characters the paced line still carries when the next write goes out (see
/// DripOptions::xoff_allowance); 0 when the chunk leaves no room.
size_t leadCharacters(const DripOptions& options);

/// \brief What a feed will send: the file, where it starts, and what is restated before.
struct DripPlan
{
  std::string path;
  ProgramScan scan;      ///< counts, start line, computed preamble
  std::string preamble;  ///< lines (separated by '\n') sent before the start line; "" for none
  bool send_leading_percent = true;
  bool send_trailing_percent = true;
  uint64_t total_bytes = 0;  ///< everything that will go on the wire, framing included
};

/// \brief The characters of restart blocks \p preamble the control cannot take, as planDrip() sends
/// them: blank lines left out, a CR ending a line dropped (the feed sends its own end of block);
/// lines numbered from 1 among those sent. The one check of a preamble, for dnc_node's ~plan_drip
/// and every feed (cnc_dnc drip, dnc_node's drip protocol).
std::vector<CharacterIssue> checkPreamble(const std::string& preamble, const CharacterRules& rules);

/// \brief Checks the program and works out what to send.
/// \param restart where to start (inactive: from the top).
/// \param preamble the user's restart blocks; when empty and restarting, the computed ones are used.
/// \throws ConfigError listing (with line numbers) the characters the control cannot take, or a
///         restart point that is not in the file. Nothing is sent by this function.
DripPlan planDrip(const std::string& path, const DripOptions& options, const RestartPoint& restart = {},
                  const std::string& preamble = "");

/// \brief Progress of a feed, given to the callback.
struct DripProgress
{
  uint64_t line = 0;    ///< file line being sent (1-based; 0 while sending the framing/preamble)
  std::string block;    ///< last sequence number sent ("N1234"), "" before any
  uint64_t bytes = 0;   ///< bytes written to the link
  uint64_t total = 0;   ///< bytes in all
  bool held = false;    ///< the control holds us (XOFF, or waiting for its DC1)
  bool paused = false;  ///< paused by the user
  uint64_t xoff_events = 0;
  double percent() const { return total == 0 ? 0.0 : 100.0 * static_cast<double>(bytes) / static_cast<double>(total); }
};

/// \brief How a feed ended.
struct DripResult
{
  enum class Outcome
  {
    kCompleted,
    kCancelled,
    kFailed
  };
  Outcome outcome = Outcome::kFailed;
  std::string message;           ///< plain words: what happened, where it stopped
  uint64_t bytes = 0;            ///< bytes written to the link
  uint64_t stopped_at_line = 0;  ///< last file line fully sent (restart after it); 0 = none
  std::string stopped_at_block;  ///< last sequence number fully sent
  uint64_t xoff_events = 0;
  /// Largest output queue when an XOFF arrived: the kernel's (TIOCOUTQ) or, when pacing, what the
  /// line still had to carry as the pacing models it, whichever is larger. It plus the write in
  /// progress is what could follow the XOFF.
  uint64_t max_queued_at_xoff = 0;
  bool completed() const { return outcome == Outcome::kCompleted; }
};

/// \brief Streams one plan to a control over a Transport.
///
/// Wire format (Fanuc/Haas tape format, docs/protocols/drip_feed.md#wire-format): [DC2] [leader] ['%' EOB] [preamble
/// blocks, each + EOB] [file lines from the start line to the last non-blank line, each + EOB]
/// ['%' EOB] [trailer] [DC4]. The framing '%' lines are sent only when the file lacks them (or a
/// restart skipped the file's first line). The control answers with DC3 (0x13, or 0x93 under 7E1
/// read as 8 bits) to stop and DC1 (0x11/0x91) to resume; any other byte it sends is ignored.
///
/// Timing: writes of `chunk` characters (4 by default), input polled before each. With pacing
/// (pace_cps), a write goes out when the line (as the sender models it) still has
/// xoff_allowance - chunk - 1 characters to carry: the line stays busy across the host's wake-up
/// latency and at most xoff_allowance characters (queued + one write + the DC3's own character
/// time) can follow an XOFF. Without
/// pacing, each write is drained (tcdrain) before the next. Memory does not depend on the program
/// size.
///
/// Thread-safety: send() runs in one thread; pause(), resume(), cancel() and held() may be called
/// from any thread. The Transport must not be used by anyone else during send(). For software flow
/// control the port must be opened WITHOUT kernel IXON, or the kernel would swallow DC3 itself.
class DripSender
{
 public:
  using ProgressCallback = std::function<void(const DripProgress&)>;
  /// Called after each file line has been written whole: its 1-based number and its text.
  using LineCallback = std::function<void(uint64_t line, const std::string& text)>;

  /// \throws ConfigError if the options are invalid.
  DripSender(Transport& link, DripOptions options);

  /// \brief Sends the plan. Returns when the program has been sent, cancelled or has failed; the
  /// result tells which and where it stopped. Never throws for link or timeout errors (they are
  /// in the result); the link stays usable after a cancel.
  DripResult send(const DripPlan& plan, const ProgressCallback& progress = nullptr,
                  const LineCallback& line_sent = nullptr);

  void pause() { paused_ = true; }
  void resume() { paused_ = false; }
  void cancel() { cancelled_ = true; }
  bool held() const { return held_; }
  bool paused() const { return paused_; }

 private:
  class Stopped;  // thrown inside send() to unwind on cancel
  /// What of the program went out, for the result of a feed however it ends.
  struct SentSoFar
  {
    uint64_t last_line = 0;  ///< the last line sent whole
    std::string last_block;  ///< its sequence number, or the last one before it
  };
  // The parts of send(), in order.
  void startFeed(const DripPlan& plan, const ProgressCallback& progress);
  /// DC2, the leader, the leading '%' and the restart preamble.
  void sendOpening(const DripPlan& plan);
  /// The program's lines from the start line to its last text line.
  void sendBody(const DripPlan& plan, LineReader& reader, std::deque<std::pair<uint64_t, std::string>>& head,
                const LineCallback& line_sent, SentSoFar& sent);
  /// The trailing '%', the trailer and DC4, then waits until they are on the wire.
  void sendClosing(const DripPlan& plan);
  std::string cancelMessage(const SentSoFar& sent) const;
  DripResult endFeed(DripResult result, const SentSoFar& sent);
  void emit(const char* data, size_t size);
  /// The lines before the program's first block and that block, read and handed to
  /// DripOptions::check_head (nothing when it is not set). \throws what the check throws.
  std::deque<std::pair<uint64_t, std::string>> readAndCheckHead(LineReader& reader) const;
  void gate();
  bool cancelRequested() const { return cancelled_ || (options_.cancel != nullptr && *options_.cancel); }
  void pollInput(Milliseconds timeout);
  void report(bool force);
  size_t queuedNow() const;

  Transport& link_;
  DripOptions options_;
  std::atomic<bool> paused_{false};
  std::atomic<bool> cancelled_{false};
  std::atomic<bool> held_{false};
  bool waiting_for_dc1_ = false;
  std::chrono::steady_clock::time_point held_since_;
  std::chrono::steady_clock::time_point line_free_at_;
  std::chrono::steady_clock::time_point last_report_;
  std::string chunk_;
  DripProgress progress_;
  ProgressCallback callback_;
  uint64_t max_queued_at_xoff_ = 0;
};
}  // namespace dnc
}  // namespace cnc_bridge
