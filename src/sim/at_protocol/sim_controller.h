// The simulated '@' controller: the real-time Linux controller of the ESPRIT paper's sections 5 and 6
// (docs/protocols/at_protocol.md#source) without the machine, as a class the sim_at_controller program runs
// (src/sim/sim_at_controller.cpp: options, signals, stdin). It serves the command socket
// ('@'-terminated messages, the ESPRIT paper's server_recv) and sends reports one per line (server_send),
// either as a server the node connects to or as a client of the node's report server. Every 1 ms
// time loop it takes one setpoint and the axes follow it with a first-order lag; it reports
// position, mode, home and emergency stop, and ignores jog requests while machining as the
// original controller does.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <deque>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/at_protocol/sequencer.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/tcp.h"

namespace cnc_bridge
{
namespace at_protocol
{
struct SimControllerOptions
{
  std::string host = "127.0.0.1";
  uint16_t command_port = 0;
  std::string report_mode = "server";
  std::string report_host = "127.0.0.1";
  uint16_t report_port = 0;
  double lag_ms = 5.0;        // first-order time constant of the axes
  int report_period_ms = 10;  // position reports while moving
  int heartbeat_ms = 1000;    // position report while idle
  double home_speed = 20.0;   // mm/s towards home
  double jog_speed = 0.0;     // mm/s that the jog feed F255 stands for; 0: jog mode moves nothing
  std::array<int32_t, 3> home{0, 0, 0};
  std::string fault_script;
  std::string pid_file;
  std::string command_log;        // every command message received, one per line, for tests to inspect
  bool estop_unreported = false;  // no E report on connection: a controller that reports only changes
};

/// One fault-script line: after the n-th setpoint received, switch the emergency stop or drop the
/// command connection.
struct SimFault
{
  enum class Action
  {
    kEStopOn,
    kEStopOff,
    kDropCommandLink
  };
  uint64_t after_setpoints = 0;
  Action action = Action::kEStopOn;
};

/// \brief The controller. run() serves until \p stop is requested; the other members may be
/// called from other threads (setEStop and toggleReportOutage from signal handlers).
class SimController
{
 public:
  /// \throws ConfigError for a fault script or command log that cannot be read or opened.
  SimController(SimControllerOptions options, StopSignal& stop);

  /// Opens the sockets and runs the control loop until stopped; prints the arrival statistics.
  void run();

  /// Emergency stop from a signal, stdin or the fault script. Thread-safe.
  void setEStop(bool on) { estop_request_ = on ? 1 : 0; }
  /// Starts or ends a report link outage (SIGHUP). Async-signal-safe: one lock-free atomic.
  void toggleReportOutage() { report_outage_.fetch_xor(1); }
  /// A line typed on stdin ("estop on", "auto", "jog X", "home"), taken by the control loop.
  void console(const std::string& line);

 private:
  // ---- command socket ----
  void commandLoop(TcpServer& server);

  /// Appends a received message (as it arrived, without its '@') to --command-log; flushed at once
  /// so a test reads what the controller has received so far.
  void logCommand(const std::string& message);

  // ---- report socket ----
  void setReportLink(std::shared_ptr<TcpConnection> link);
  bool reportLinkUp();
  void reportServerLoop(TcpServer& server);
  void reportClientLoop();

  /// Closes the report connection while an outage (SIGHUP) lasts.
  void dropReportLinkDuringOutage();

  /// Writes one report; a failed write drops the link (the report loop connects or accepts again).
  void report(const Report& report);
  PositionReport positionReport() const;
  void reportMode();

  // ---- stdin ----
  void consoleLoop();
  void handleConsole(const std::string& line);

  // ---- the 1 ms time loop ----
  void apply(const Command& command);
  void controlLoop();
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  // What the time loop reported last, which paces the position reports.
  struct ReportPacing
  {
    std::array<double, 3> last_reported{kNaN, kNaN, kNaN};
    uint64_t last_tick = 0;
    bool was_moving = false;
  };
  // One time loop's steps, in order.
  void takeCommands();
  void greet(uint64_t tick, ReportPacing& pacing);
  void takeEStopRequest();
  void moveAxes(double dt, double alpha);
  void homeStep(double dt);
  void reportPosition(uint64_t tick, ReportPacing& pacing);

  SimControllerOptions options_;
  StopSignal& stop_;
  std::vector<SimFault> faults_;

  std::mutex mutex_;  // guards queue_, console_, arrivals bookkeeping
  std::deque<Command> queue_;
  std::deque<std::string> console_;
  bool new_command_link_ = false;  // the control loop resets the sequencer; guarded by mutex_
  std::ofstream command_log_;      // guarded by mutex_
  int64_t last_arrival_ns_ = 0;
  IntervalHistogram arrivals_;
  std::atomic<uint64_t> ignored_{0};

  std::mutex report_mutex_;
  std::shared_ptr<TcpConnection> report_link_;
  std::atomic<bool> greet_{false};
  std::atomic<int> estop_request_{-1};
  std::atomic<bool> drop_command_link_{false};  // set by the fault script, taken by the command loop
  std::atomic<int> report_outage_{0};           // SIGHUP toggles it (int: fetch_xor)

  // Owned by the control loop.
  Sequencer sequencer_;
  std::optional<Axis> jog_axis_;
  bool estop_ = false;
  bool homing_ = false;
  bool at_home_reported_ = false;
  uint64_t setpoints_received_ = 0;
  std::array<double, 3> position_{0, 0, 0};
  std::array<double, 3> target_{0, 0, 0};
};
}  // namespace at_protocol
}  // namespace cnc_bridge
