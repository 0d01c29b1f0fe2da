// The host's side of one '@' controller (docs/protocols/at_protocol.md, docs/at_controller_node.md):
// both TCP links kept open (commands out, reports in), the reports folded into what the controller
// last said, the motion gate (enabled, e-stop), the commands of the services in the protocol's
// units, and a goal planned and run as operations through the 1 ms sender. ROS-free: the node maps
// parameters to its options and its listener's events to state, topics and diagnostics.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/deadman.h"
#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/program_path.h"
#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/common/soft_limits.h"
#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// The controller's emergency stop as the host knows it.
enum class EStop : uint8_t
{
  kUnknown,  ///< no E0/E1 on the current report connection (or no report connection): not clear
  kOff,      ///< E0
  kOn        ///< E1
};

/// \brief What the controller reported last, folded from its report stream.
struct ControllerSnapshot
{
  EStop estop = EStop::kUnknown;
  int jog_axis = -1;                  ///< 0..2 after a J? report; -1 after A (or before any mode report)
  std::array<int32_t, 3> position{};  ///< pulses
  bool position_valid = false;        ///< a position report has arrived
  /// When the last position report arrived (the epoch before the first).
  std::chrono::steady_clock::time_point position_at{};
  bool at_home = false;  ///< H reported, and no move since
};

/// \brief One report as it changed the snapshot, with the words the node shows for it.
struct ReportEvent
{
  enum class Kind
  {
    kEStop,     ///< estop changed (E1 also aborted a running operation)
    kMode,      ///< jog_axis changed (A or J?)
    kPosition,  ///< position changed (no message)
    kHome       ///< at_home set
  };
  Kind kind;
  std::string message;  ///< "emergency stop (E1)", "auto mode", "jog mode, axis Y", "at home"
};

/// \brief A jog stopped by its deadman (ControllerSession::expireJog).
struct JogStop
{
  bool sent = false;    ///< F0@ went out
  std::string why;      ///< "jog stopped: no jog command for 0.5 s"
  std::string failure;  ///< why F0@ could not be sent ("" if it was)
};

/// \brief Events of the session, called on the link threads (a jog's stop on the deadman's),
/// without the session's locks held.
class ControllerListener
{
 public:
  virtual ~ControllerListener() = default;
  /// \p combined is UP only when both links are; \p why names the link that changed and its
  /// failure ("report link: ..."), empty when there is none. \p reports_lost: the report link is
  /// not up, so the e-stop became unknown. Calls come one at a time, in order.
  virtual void onLink(LinkState combined, const std::string& why, bool reports_lost) {}
  virtual void onReport(const ReportEvent& event, const ControllerSnapshot& now) {}
  /// A report line that could not be read (counted in reportErrors()).
  virtual void onReportError(const std::string& what) {}
  /// The deadman stopped a jog: no jog command came within Options::jog_timeout (lastJogStop()).
  virtual void onJogStopped(const JogStop& stop) {}
};

/// \brief How the two links are opened: each opener blocks until its link is open, or throws.
struct ControllerLinks
{
  ReconnectingLink::Opener open_command;
  std::string command_name;  ///< for log lines: "at_controller command link 10.0.0.7:5000"
  ReconnectingLink::Opener open_report;
  std::string report_name;
  /// Wakes an opener that waits for the peer (a report server's accept) when the session stops.
  std::function<void()> stop_opening;
};

/// \brief Where the controller's servers are (docs/at_controller_node.md, parameters).
struct TcpLinkSettings
{
  /// The controller's command server (the ESPRIT paper's server_recv); its host and connect timeout are
  /// the report link's too.
  LinkSettings command = LinkSettings::tcp("127.0.0.1", 5000, Milliseconds(2000));
  bool report_server = false;   ///< we listen for the controller's report connection
  uint16_t report_port = 5001;  ///< the controller's report server (client mode)
  uint16_t listen_port = 5001;  ///< our report server (server mode); 0: any free port

  /// \brief The report link in client mode: the command link's host, report_port.
  LinkSettings reportLink() const;
};

/// \brief Openers for both links (the link factory's; in server mode the report link is accepted by
/// a report server, which listens from here on).
/// \param listening_on set to the report server's address in server mode ("0.0.0.0:5001").
/// \throws ConfigError for invalid link settings, LinkError if the report server cannot listen.
ControllerLinks tcpLinks(const TcpLinkSettings& settings, std::string* listening_on = nullptr);

/// \brief A goal of follow_path without ROS types (docs/at_controller_node.md, the action).
struct GoalRequest
{
  std::string gcode_file;      ///< in the program directory; empty for a path
  bool has_path = false;       ///< the goal gave path poses (path_m holds them in the machine frame)
  std::vector<Vec3> path_m;    ///< metres, machine frame
  double feed_rate = 0.0;      ///< m/s; 0: the program's F words or the default feed
  int coolant = -1;            ///< -1: the session's coolant setting; 0 off; 1 on
  double spindle_speed = 0.0;  ///< rev/min; 0: the program's S word, if any
  int32_t tool = -1;           ///< tool change before the first operation; -1: none
  double tool_length = 0.0;    ///< m, with \c tool
};

/// \brief Where an operation came to rest when motion was disabled during it.
struct DisabledStop
{
  std::string by;         ///< who disabled motion
  Vec3 position{};        ///< pulses, the last setpoint (the controller holds it)
  double distance = 0.0;  ///< pulses along the operation's path
  uint64_t sent = 0;      ///< setpoints of the operation sent
  uint64_t planned = 0;   ///< setpoints the operation had
};

/// \brief One operation as it ended (see ControllerSession::runOperation).
struct OperationResult
{
  std::shared_ptr<const Job> job;        ///< ended: state(), message(), sent(), current()
  bool cancelled = false;                ///< the caller asked for the cancel
  uint64_t underruns = 0;                ///< during this operation
  std::optional<DisabledStop> disabled;  ///< decelerated to a stop because motion was disabled
};

/// \brief A service's answer: success, or the refusal or failure in words.
struct Answer
{
  bool success = false;
  std::string message;
};

/// \brief The session with one '@' controller. Thread-safe; start() once, stop() (or the
/// destructor) before the listener goes away. A jog's deadman runs on a thread of its own: a jog
/// not renewed within Options::jog_timeout gets feed 0 (expireJog) and the listener is told.
class ControllerSession
{
 public:
  struct Options
  {
    SetpointSender::Options sender;    ///< on_link_error is the session's own
    PlannerLimits limits;              ///< mm, mm/s, ... (planner units)
    double spindle_max_rpm = 24000.0;  ///< rev/min that S255 stands for
    SoftLimits soft_limits;            ///< every point of a goal must lie inside (m, machine frame)
    double default_feed = 0.01;        ///< m/s when neither goal nor program gives one
    double jog_timeout = 0.5;          ///< s, the jog deadman (0: off)
    bool motion_enabled = false;       ///< the motion switch's start value, when `motion` is not given
    /// The node's motion switch: the session gates motion on it and acts on its changes (a
    /// disable decelerates a running path, stops a jog); none: a switch of its own.
    std::shared_ptr<SafetySwitch> motion;
    bool coolant = false;  ///< coolant of operations unless a goal says otherwise
    gcode::ParserOptions gcode;
    std::string program_dir;                          ///< G-code goals are read here only; empty refuses them
    std::string program_dir_setting = "program_dir";  ///< named in that refusal
    /// The refusal while motion is disabled ("jog refused: motion is disabled; enable it with ...").
    std::function<std::string(const std::string& what)> disabled_refusal;
  };

  ControllerSession(ControllerLinks links, Options options, ControllerListener* listener = nullptr);
  ~ControllerSession();
  ControllerSession(const ControllerSession&) = delete;
  ControllerSession& operator=(const ControllerSession&) = delete;

  /// \brief Starts both links' threads (each connects, and reconnects after a backoff).
  void start();
  /// \brief Stops both links and the sender's use of them; no listener call after it returns.
  void stop();

  ControllerSnapshot snapshot() const;
  /// \brief Waits until \p done holds for the snapshot (asked at once and after each report, with
  /// the session's lock held: it must not call the session), \p cancelled() (asked every 100 ms)
  /// or \p deadline. \returns the snapshot it ended with.
  ControllerSnapshot waitForReport(const std::function<bool(const ControllerSnapshot&)>& done,
                                   std::chrono::steady_clock::time_point deadline,
                                   const std::function<bool()>& cancelled) const;
  uint64_t reportErrors() const { return report_errors_.load(); }
  unsigned commandReconnects() const { return command_link_.reconnects(); }
  unsigned reportReconnects() const { return report_link_.reconnects(); }
  SetpointSender& sender() { return *sender_; }
  const Options& options() const { return options_; }
  Deadman& jogDeadman() { return jog_deadman_; }
  /// \returns the deadman's last stop in words ("jog stopped: no jog command for 0.5 s", with the
  /// failure if F0@ could not be sent), "" if it has not stopped a jog.
  std::string lastJogStop() const;

  // ---- the motion gate --------------------------------------------------------------------------

  /// \brief Switches the motion switch (Options::motion). On each change, by this call or by
  /// the switch's owner, disabling cancels a running operation (it decelerates along the path to
  /// a stop; runOperation() reports who disabled it), and stops a jog (F0@).
  void setMotionEnabled(bool enabled, const std::string& by);
  bool motionEnabled() const { return motion_->enabled(); }
  /// \returns the motion switch the session gates on (Options::motion, or its own).
  SafetySwitch& motionSwitch() { return *motion_; }
  /// \returns who disabled motion last ("" if nobody has).
  std::string motionDisabledBy() const;
  /// \returns why \p what may not move now (motion disabled, e-stop on or unknown), or "".
  std::string motionRefusal(const std::string& what) const;

  // ---- commands (the services) ------------------------------------------------------------------

  /// \brief Queues \p commands and waits until each is written (2 s at most each).
  /// \returns "sent A@" or why not.
  Answer send(const std::vector<Command>& commands);
  /// \brief A@; ends a jog (the deadman is disarmed).
  Answer setAuto();
  /// \brief J<axis>@ F<n>@ with n the feed as a share of the axis' top speed; refused unless
  /// motion may start. A moving jog arms the deadman, feed 0 disarms it.
  Answer jog(const std::string& axis, double feed_m_s);
  /// \brief S<n>@; starting (n > 0) is refused unless motion may start, stopping never is.
  /// \param sent_rpm set to the speed the value sent stands for.
  Answer spindle(double rpm, double* sent_rpm = nullptr);
  /// \brief T<tool> <mm>@; refused unless motion may start.
  Answer toolChange(int32_t tool, double length_m);
  /// \brief H@; refused unless motion may start.
  Answer home();
  /// \brief If the deadman of a jog expired at \p now, sends F0@ and \returns the stop; nothing
  /// if it did not expire (\p remaining is then the time left, zero when it is not armed). The
  /// session's deadman thread calls it when the deadline comes.
  std::optional<JogStop> expireJog(Deadman::Clock::time_point now, Deadman::Clock::duration* remaining);
  /// \brief The coolant of the next operations (the protocol switches it only with one).
  void setCoolant(bool on) { coolant_ = on; }
  bool coolant() const { return coolant_.load(); }

  // ---- goals ------------------------------------------------------------------------------------

  /// \brief The goal as operations in pulses, the first from \p start: one for a path; for a
  /// program, one per stretch of moves between its own steps (planProgram).
  /// \param program_commands, program_commands_setting see ProgramPlanOptions.
  /// Every operation's tool change and spindle speed are checked here, before anything is sent.
  /// \throws Error (ConfigError, gcode::ParseError) with the reason (a value the wire cannot carry:
  /// the operation and the value).
  std::vector<OperationPlan> planGoal(const GoalRequest& goal, const std::array<int32_t, 3>& start,
                                      bool program_commands, const std::string& program_commands_setting) const;
  /// \brief Checks every operation's tool change and spindle value before the first is sent.
  /// \throws ConfigError naming the operation and the value if the wire cannot carry one.
  void checkPlans(const std::vector<OperationPlan>& plans, int32_t goal_tool, double goal_tool_length) const;
  /// \brief What the sender sends for \p plan: P@, T@ (with the goal's tool length if it is the
  /// goal's tool), S@ in the protocol's units, and the trajectory.
  /// \throws ProtocolError if the spindle speed or the tool change cannot be sent exactly.
  Operation operationFor(const OperationPlan& plan, int32_t goal_tool, double goal_tool_length) const;

  /// What runOperation() asks its caller while the operation runs (on the caller's thread).
  struct OperationWatch
  {
    std::function<void(const Job&)> started;                  ///< once, after the sender took it
    std::function<bool()> cancel_requested;                   ///< polled every 100 ms
    std::function<void(const Job&, bool stopping)> progress;  ///< every 100 ms and at the end
  };
  /// \brief Runs \p operation (of \p plan) to its end on the calling thread: ends a jog, streams
  /// it, cancels it (a deceleration along the path) once the watch asks; a disable of motion
  /// cancels it too and is reported as OperationResult::disabled.
  /// \throws ProtocolError, LinkError as SetpointSender::start.
  OperationResult runOperation(const OperationPlan& plan, const Operation& operation, const OperationWatch& watch);

 private:
  void onMotionSwitched(bool enabled, const std::string& by);
  /// \brief The tool change and spindle value of \p plan into \p operation (if given).
  /// \throws ProtocolError if one cannot be sent exactly (toolChangeFor, scaledValue).
  void operationCommands(const OperationPlan& plan, int32_t goal_tool, double goal_tool_length,
                         Operation* operation = nullptr) const;
  std::unique_ptr<Transport> openCommandLink();
  void commandSession();
  void reportSession(Transport& link);
  void onReport(const Report& report);
  void linkChanged(int which, LinkState state, const std::string& why);
  void notifyReport(ReportEvent::Kind kind, const std::string& message);
  Deadman::Clock::duration checkJogDeadman();

  Options options_;
  ControllerListener* listener_;
  ControllerLinks links_;
  std::unique_ptr<ProgramDirectory> program_dir_;
  std::unique_ptr<SetpointSender> sender_;
  Deadman jog_deadman_;
  std::atomic<bool> coolant_;
  std::shared_ptr<SafetySwitch> motion_;
  SafetySwitch::Subscription motion_subscription_ = 0;
  std::atomic<uint64_t> report_errors_{0};

  mutable std::mutex snapshot_mutex_;            // guards snapshot_, link_states_
  mutable std::condition_variable snapshot_cv_;  // a report changed snapshot_
  ControllerSnapshot snapshot_;
  LinkState link_states_[2] = {LinkState::kDown, LinkState::kDown};  // command, report
  std::mutex link_change_mutex_;                                     // listener's onLink calls one at a time, in order

  std::mutex command_mutex_;  // guards command_failed_, command_interrupted_, command_error_
  std::condition_variable command_cv_;
  bool command_failed_ = false;       // the sender's write failed
  bool command_interrupted_ = false;  // the reconnecting link interrupted the link (stop)
  std::string command_error_;

  mutable std::mutex job_mutex_;  // guards running_job_, disabled_by_
  std::shared_ptr<Job> running_job_;
  std::string disabled_by_;  // who disabled motion while running_job_ ran

  mutable std::mutex jog_stop_mutex_;  // guards last_jog_stop_
  std::string last_jog_stop_;

  ReconnectingLink command_link_;
  ReconnectingLink report_link_;
  DeadmanTimer jog_timer_;  // last: stopped before what its checks use goes away
};
}  // namespace at_protocol
}  // namespace cnc_bridge
