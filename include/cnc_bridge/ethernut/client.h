// The PC side of the ethernut protocol: qCNC's TCP_control() as a session over a Transport.
// It connects (init request, ack), selects the board's mode, streams a job's coordinates one at a
// time with NEXT/RESEND, keeps the link alive, and carries the operator's commands (pause,
// resume, reset, kill, mode switch) to the board while a job runs.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "cnc_bridge/ethernut/protocol.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace ethernut
{
/// Where the session is in qCNC's TCP_control() flow.
enum class SessionState : uint8_t
{
  kDisconnected,  ///< run() not running
  kInitialising,  ///< handshake: init request and then the initial mode, each waiting for its ack
  kConnected,     ///< both acknowledged (the mode is known); READYTOSEND not (yet) requested
  kWaitingReady,  ///< READYTOSEND requested for a job
  kReadyToSend,   ///< the board takes coordinates; none in flight
  kSending,       ///< a coordinate is in flight, waiting for NEXT or RESEND
  kPaused,        ///< pause achieved; resume returns to the state before the pause
  kKilled,        ///< kill acknowledged: the board stopped everything and drops the link
  kStandalone     ///< standalone mode acknowledged: the board drops its TCP clients
};
const char* toString(SessionState state);

/// The board's operating mode (opcode rows 5-7).
enum class BoardMode : uint8_t
{
  kUnknown,
  kFile,        ///< (15, 15) file transaction mode: coordinates come from a file over TCP
  kGuiControl,  ///< (15, 6) coordinates come from the GUI's controls
  kStandalone   ///< (15, 9) the board runs from its own panel and drops TCP clients
};
const char* toString(BoardMode mode);
/// \brief The mode named \p text ("file", "gui-control", "standalone", as toString() writes it).
/// \returns false for any other text (\p mode unchanged).
bool parseBoardMode(const std::string& text, BoardMode& mode);

/// One set of coordinates for the board, mm (the board's unit), plus the caller's tag (e.g. the
/// G-code line it came from), which is not sent.
struct Coordinate
{
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  uint32_t tag = 0;
};

enum class JobOutcome : uint8_t
{
  kCompleted,  ///< every coordinate got its NEXT
  kCancelled,  ///< cancelJob(), reset() or kill()
  kFailed      ///< too many RESENDs for one coordinate, or the link failed
};

struct ClientOptions
{
  /// How long a command (init, mode, pause, READYTOSEND, reset, kill) waits for the board's answer.
  Milliseconds reply_timeout{2000};
  /// After this long without any message from the board, send an alive request (row 17).
  Milliseconds keepalive_period{500};
  /// After this long without any message from the board, the link is dead (qCNC's INET_DEL).
  Milliseconds dead_link_timeout{2000};
  /// RESENDs accepted for one coordinate before the job fails.
  unsigned max_resends = 5;
  /// Kill commands (row 9) are refused unless this is set (qCNC's PROG_CNCkill).
  bool kill_enabled = false;
  /// Table 1 lists a global acknowledge as the response to a position report (row 4); off for
  /// boards that do not expect it.
  bool ack_position_reports = true;
  /// Mode selected after every (re)connection.
  BoardMode initial_mode = BoardMode::kFile;
  /// An alive request also goes out when none was sent for this long, however busy the link, so
  /// that the link round trip is measured while jobs stream too; 0: only on silence.
  Milliseconds rtt_probe_period{5000};
  /// Longest wait inside one read, which bounds how late a command from another thread is sent.
  Milliseconds poll_interval{10};
};

/// Counters for diagnostics. Two round-trip times: coordinate sent -> NEXT received (the board
/// answers once it has moved there, so this includes the move), and alive request -> alive
/// response (the link's own round trip: network plus the board's TCP task).
struct ClientStats
{
  uint64_t coordinates_sent = 0;  ///< including resends
  uint64_t coordinates_done = 0;  ///< NEXT received
  uint64_t resends = 0;
  uint64_t keepalive_requests = 0;
  uint64_t keepalive_misses = 0;  ///< alive requests that were not answered before the next one
  uint64_t bad_frames = 0;        ///< NaN/inf frames received
  uint64_t unexpected_messages = 0;
  uint64_t connections = 0;
  double last_rtt_ms = 0.0;
  double mean_rtt_ms = 0.0;  ///< exponential average (1/16 weight per sample)
  double max_rtt_ms = 0.0;
  uint64_t alive_responses = 0;  ///< answers to our alive requests (link round-trip samples)
  double last_link_rtt_ms = 0.0;
  double mean_link_rtt_ms = 0.0;  ///< exponential average (1/16 weight per sample)
  double max_link_rtt_ms = 0.0;
  float last_board_error = 0.0f;  ///< last non-zero `error` field from the board
};

/// \brief Adds the counters of \p more to \p total (not the round-trip times, which are per
/// connection), e.g. to count across reconnections.
void addCounters(ClientStats& total, const ClientStats& more);

/// \brief Events from the session, called on the thread that runs Client::run(), without the
/// client's lock held. Do not call blocking Client commands from them (they would wait for the
/// thread that is calling you); state queries are fine.
class ClientListener
{
 public:
  virtual ~ClientListener() = default;
  virtual void onState(SessionState state, SessionState previous) {}
  /// A status-4 message: the machine's reported position, mm.
  virtual void onPosition(float x, float y, float z) {}
  /// The board sent NEXT for coordinate \p index (0-based within the job).
  virtual void onCoordinateDone(uint64_t index, const Coordinate& coordinate) {}
  /// The board asked for coordinate \p index again; \p count for this coordinate so far.
  virtual void onResend(uint64_t index, unsigned count) {}
  virtual void onJobFinished(JobOutcome outcome, const std::string& message) {}
  /// A message carried a non-zero error field (the board's 0-9 error code).
  virtual void onBoardError(float code) {}
};

/// \brief The PC/client task of the ethernut protocol (docs/protocols/ethernut.md#session).
///
/// Protocol, as implemented (opcodes in protocol.h; every PC message is answered by exactly one
/// board message, so one command is outstanding at a time and coordinates are stop-and-wait):
///   connect:   PC init-request (200,78) -> board ack (200,101); PC mode (15,15|6|9) -> ack.
///   job:       PC READYTOSEND (200,50) -> ack; then PC coordinates (1,x,y,z) -> NEXT (200,30)
///              (send the next set) or RESEND (200,60) (send the same set again, at most
///              max_resends times). A bare ack after coordinates is read as NEXT (Table 1 lists
///              16 as the response of row 1).
///   keepalive: when the board has been silent for keepalive_period (or no alive request went
///              out for rtt_probe_period), PC alive-request (200,199) -> board alive-response
///              (200,999), timed as the link round trip. The board's alive request is answered
///              with an alive response at any time. Any message from the board proves the link;
///              dead_link_timeout of silence is a dead link (run() throws LinkError).
///   pause:     PC pause-request (99,199) -> board pause-achieved (99,201). Rows 10/11 are read
///              as request and answer: the board sends pause-achieved once motion has stopped
///              (the "must be responded to (10)" of row 11 names the request it answers). A
///              pause-achieved that arrives unasked (a hold on the board's panel) pauses too.
///   resume:    not in the table; qCNC says resume "falls back into its previous state".
///              We resume with READYTOSEND (200,50) -> ack: the board continues the held move
///              and answers the coordinate in flight with NEXT as usual.
///   reset:     (99,0) -> ack; the job is cancelled, the board clears and goes to 0/0/0. The
///              qCNC's "reset" and "clear" share this one opcode; we keep the link (clear).
///   kill:      (99,99) -> ack, then the board stops and drops the link (refused here unless
///              kill_enabled).
///   position:  the board's (4,x,y,z) at any time -> ack (if ack_position_reports).
///
/// Thread-safe: run() on one thread (it alone touches the Transport); every other method from
/// any other thread.
class Client
{
 public:
  /// \param transport connected link to the board; must outlive the client.
  /// \param listener optional; must outlive the client.
  Client(Transport& transport, const ClientOptions& options, ClientListener* listener = nullptr);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  /// \brief Runs the session on the calling thread: handshake, then serve until stop(), kill or
  /// standalone mode (returns) or until the link fails (throws).
  /// \throws LinkError (peer gone, dead link, init not acknowledged), CancelledError.
  void run();
  /// \brief Makes run() return within poll_interval. Thread-safe.
  void stop();

  /// \brief Starts streaming the coordinates \p source yields (false: no more).
  /// \p source is called on the run() thread. Returns at once; progress and the end come
  /// through the listener (onCoordinateDone, onJobFinished).
  /// \throws LinkError if not connected, ProtocolError if a job is running or the board is paused.
  void startJob(std::function<bool(Coordinate&)> source);
  /// \brief Stops streaming; the job ends with kCancelled. The coordinate in flight (if any) is
  /// not taken back: the board finishes or holds it, and the next job's first coordinate is sent
  /// only after the board answered it (the session stays kSending until then). Does nothing
  /// without a job.
  void cancelJob();
  /// \brief Pause request; returns once the board reported pause achieved.
  /// \throws TimeoutError, LinkError.
  void pause();
  /// \brief Back to the state before the pause. \throws ProtocolError if not paused, TimeoutError.
  void resume();
  /// \brief Reset/clear: cancels the job, the board clears and goes to 0/0/0.
  void reset();
  /// \brief Kill. \throws DisabledError unless ClientOptions::kill_enabled.
  void kill();
  /// \brief Switches the board's mode. Standalone makes the board drop the link: run() returns.
  void setMode(BoardMode mode);
  /// \brief Rows 2 and 3 ("TODO" on qCNC's board): sent and acknowledged, meaning is the board's.
  void syncOled(float x, float y, float z);
  void sendCommand(float x, float y, float z);

  SessionState state() const;
  BoardMode mode() const;
  bool jobActive() const;
  ClientStats stats() const;
  const ClientOptions& options() const { return options_; }

 private:
  struct Completion;
  struct Request
  {
    Message message;
    Opcode opcode;
    Opcode expect;
    std::shared_ptr<Completion> done;  // null for internal requests
  };
  struct Job
  {
    std::function<bool(Coordinate&)> source;
    uint64_t index = 0;  // of the coordinate in flight or next to send
    Coordinate current;
    bool in_flight = false;
    unsigned resends = 0;
    bool resend_pending = false;  // RESEND while paused: send again on resume
  };
  using Clock = std::chrono::steady_clock;

  void command(Opcode opcode, float x = 0, float y = 0, float z = 0);
  void send(const Message& message);
  void sendRequest(std::unique_lock<std::mutex>& lock, Request request);
  void handle(std::unique_lock<std::mutex>& lock, const Message& message);
  void onBoardError(std::unique_lock<std::mutex>& lock, float code);
  void onAck(std::unique_lock<std::mutex>& lock, const Message& message);
  void onNext(std::unique_lock<std::mutex>& lock);
  void onResend(std::unique_lock<std::mutex>& lock);
  void onPauseAchieved(std::unique_lock<std::mutex>& lock);
  void onAliveResponse();
  void onPosition(std::unique_lock<std::mutex>& lock, const Message& message);
  void beginRun();
  void serve(std::unique_lock<std::mutex>& lock);
  void receive(std::unique_lock<std::mutex>& lock, StreamDecoder& decoder, const uint8_t* data, size_t n,
               unsigned& bad_in_a_row);
  void endRun(std::unique_lock<std::mutex>& lock, const std::string& failure);
  /// A NEXT/RESEND with no job set in flight: the answer to the set of a cancelled job, if one
  /// was still in flight (the session leaves kSending); false otherwise.
  bool orphanAnswered(std::unique_lock<std::mutex>& lock);
  void pump(std::unique_lock<std::mutex>& lock);
  void sendCurrent(std::unique_lock<std::mutex>& lock);
  void setState(std::unique_lock<std::mutex>& lock, SessionState state);
  void finishJob(std::unique_lock<std::mutex>& lock, JobOutcome outcome, const std::string& message);
  void completePending(std::unique_lock<std::mutex>& lock, const std::string& error);
  void failAll(std::unique_lock<std::mutex>& lock, const std::string& error);
  void checkTimers(std::unique_lock<std::mutex>& lock);

  Transport& transport_;
  const ClientOptions options_;
  ClientListener* listener_;

  mutable std::mutex mutex_;
  bool running_ = false;
  bool stop_ = false;
  bool finished_ = false;  // kill/standalone acknowledged: leave run()
  SessionState state_ = SessionState::kDisconnected;
  SessionState before_pause_ = SessionState::kConnected;
  BoardMode mode_ = BoardMode::kUnknown;
  std::deque<Request> queue_;
  bool has_pending_ = false;
  Request pending_;
  Clock::time_point pending_deadline_;
  std::unique_ptr<Job> job_;
  bool job_cancel_ = false;
  Clock::time_point last_rx_;
  Clock::time_point last_alive_sent_;
  bool alive_outstanding_ = false;
  Clock::time_point coordinate_sent_at_;
  ClientStats stats_;
};
}  // namespace ethernut
}  // namespace cnc_bridge
