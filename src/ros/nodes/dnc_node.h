// dnc_node: NC programs to and from a control over its RS-232 port. The node owns the serial link
// (opened per transfer or kept open, with a PortLock held while a transfer runs so a status poller
// on the same line stays quiet), runs one transfer at a time (a second request while one runs is
// refused: a ~transfer goal is rejected with the reason, never preempts the running one), and
// dispatches each transfer to a protocol handler by name. XModem (xmodem, xmodem-crc, xmodem-1k) is registered here;
// other protocols (drip-feed, backup) register with registerProtocol() in the constructor. With
// ~requests, a thread listens on the idle port for request programs the control punches
// (src/ros/nodes/dnc_requests.cpp) and leaves the port to any transfer asked for meanwhile.
#pragma once

#include <ros/ros.h>

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/dnc/dnc_settings.h"
#include "cnc_bridge/dnc/program_requests.h"
#include "cnc_bridge/dnc/transfer_gate.h"
#include "cnc_bridge/dnc/transfer_rules.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/xmodem/file_transfer.h"

namespace cnc_bridge
{
/// \brief One transfer as a protocol handler sees it.
struct TransferJob
{
  TransferGoal goal;  ///< as requested (protocol already defaulted to ~xmodem_mode)
  std::string path;   ///< goal.file resolved inside ~program_dir
  bool send = true;   ///< direction == send
  /// For a send: checks the bytes read to be sent (the protected range), before the first goes out.
  std::function<void(const std::string& contents)> check_contents;
};

/// \brief Moves one file over \p link. Reports progress through \p feedback (throttled by the
/// node), stops with CancelledError when \p cancel is set (the link is interrupted too), and
/// returns the result or throws a cnc_bridge::Error whose message becomes the result message.
using ProtocolHandler = std::function<TransferResult(Transport& link, const TransferJob& job,
                                                     const std::function<void(const TransferFeedback&)>& feedback,
                                                     const std::atomic<bool>& cancel)>;

/// \brief The dnc_node. Services and the action may be called from any spinner thread.
/// \brief dnc_node's parameters as settings (dnc_params.cpp). \throws ConfigError naming a bad one.
dnc::TransferSettings dncSettings(const ros::NodeHandle& pnh);

class DncNode
{
 public:
  DncNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  DncNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dnc::TransferSettings& settings);
  ~DncNode();

  /// \brief Makes \p protocol available to ~transfer, ~send_program and ~receive_program.
  void registerProtocol(const std::string& protocol, ProtocolHandler handler);
  /// \brief ~program_dir, for protocol services that read programs (~plan_drip).
  const ProgramDirectory& programs() const { return *programs_; }

 private:
  using Feedback = std::function<void(const TransferFeedback&)>;
  /// Runs a job start to end for a service: refuses if busy, else as runReserved().
  TransferResult run(TransferGoal goal, const Feedback& feedback);
  /// Runs a job the caller has reserved the node for (tryReserve()): refuses a file outside
  /// ~program_dir, holds the port lock, opens the link (if not open), updates state and
  /// diagnostics. \p cancelled is set when the transfer ended because it was cancelled.
  TransferResult runReserved(TransferGoal goal, const Feedback& feedback, bool& cancelled);
  /// Checks \p job (protocol, direction, file, motion switch for a drip) and resolves its path.
  /// \returns why it is refused, "" if it may run.
  std::string checkJob(TransferJob& job);
  /// Runs \p job by \p handler on the port (the listener gone, the port lock held, the link open).
  TransferResult runOnPort(const ProtocolHandler& handler, const TransferJob& job, const std::string& transfer_message,
                           const Feedback& feedback, bool& cancelled);
  /// Counts the ended transfer, shows it in state, archives a completed one.
  void endTransfer(const TransferJob& job, const TransferResult& result, bool cancelled);
  /// Takes the node for one transfer, \p what (named in the refusal of another); false (and
  /// counted as refused) if one is running.
  bool tryReserve(const std::string& what);
  std::string busyMessage();
  /// Opens the serial port if it is not open (the only place the link is opened).
  Transport& openLink();
  void closeLink();
  /// Starts ~transfer: a goal is admitted once it has reserved the node (tryReserve()).
  void startTransferAction();
  /// Runs an admitted goal (the node reserved for it) and ends it.
  void executeGoal(const TransferGoal& goal);
  void cancelRunning();
  bool onSend(SendProgram::Request& request, SendProgram::Response& response);
  bool onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response);
  /// Keeps the program of a completed transfer in ~archive_dir (a failure there is logged only).
  void archiveProgram(const TransferJob& job);
  void transferDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);
  TransferResult runXmodem(Transport& link, const TransferJob& job,
                           const std::function<void(const TransferFeedback&)>& feedback,
                           const std::atomic<bool>& cancel);

  // Program requests punched by the control (src/ros/nodes/dnc_requests.cpp, docs/dnc_node.md).
  /// Reads the ~request* parameters; starts the listener thread if ~requests is set.
  void setUpRequests(ros::NodeHandle& nh, ros::NodeHandle& pnh);
  void stopRequests();
  /// The listener thread: while the node is idle, waits on the port for a punch and serves it.
  void requestWorker();
  /// Waits on the port (the node idle) for one punch; nothing if stopped or refused. On a punch
  /// the node is reserved for it (\p reserved set): the caller releases it.
  std::optional<dnc::Punch> listenForPunch(bool& reserved);
  /// Serves one punched program (the node reserved for it) and publishes what became of it.
  void servePunch(const dnc::Punch& punch);
  /// SAVE: the program the control punches next, into ~program_dir and the archive.
  std::string saveNextPunch(const std::string& name, bool& success);
  /// Refused request: the answer program that says why goes to the control.
  std::string answerRefusal(const dnc::Punch& punch, const std::string& shown);
  /// A received program that is a request (a punch that came during a receive transfer).
  void reportRequestInTransfer(const TransferJob& job);
  void publishRequest(ProgramRequestEvent& event);

  ros::NodeHandle nh_;
  ros::NodeHandle pnh_;
  SerialSettings serial_;
  std::unique_ptr<ProgramDirectory> programs_;
  std::unique_ptr<RuntimeSwitch> motion_;                ///< gates drip-feeds (~enable_motion)
  std::unique_ptr<programs::ProtectedRange> protected_;  ///< refused on send unless allowed
  std::unique_ptr<programs::NamePattern> name_pattern_;
  std::unique_ptr<programs::ProgramArchive> archive_;  ///< every program sent or received, versioned
  std::unique_ptr<dnc::TransferFiles> files_;          ///< what a transfer may touch, and the archiving
  std::string default_protocol_;
  bool keep_open_ = false;
  xmodem::Config xmodem_config_;
  xmodem::TextOptions text_options_;
  ros::Duration feedback_period_;

  std::map<std::string, ProtocolHandler> protocols_;
  std::unique_ptr<MachineStatePublisher> state_;
  LinkFactory open_link_;  ///< the only way the link is opened (openLink())
  PortLock port_lock_;

  /// One transfer at a time (an admitted goal holds it until its result goes out), the
  /// request listener only while none runs; its cancel flag stops the running transfer.
  dnc::TransferGate gate_;
  std::mutex link_mutex_;  ///< guards link_ for cancelRunning()
  std::unique_ptr<Transport> link_;
  uint64_t link_generation_ = 0;  ///< counts the links opened (guarded by link_mutex_)

  dnc::TransferCounters counters_;

  ros::ServiceServer send_srv_;
  ros::ServiceServer receive_srv_;
  std::unique_ptr<SingleGoalActionServer<TransferAction>> action_;  ///< ~transfer

  // Program requests (the listener's turns on the port: gate_).
  bool requests_ = false;
  std::string request_protocol_;  ///< the protocol a LOAD is answered by (~request_mode)
  dnc::RequestListenerOptions request_options_;
  programs::RequestWords request_words_;
  uint32_t answer_number_ = 1;  ///< the answer's O number when the request program has none
  std::unique_ptr<dnc::RequestListener> listener_;
  uint64_t listener_generation_ = 0;  ///< link_generation_ of the link listener_ was made for
  ros::Publisher requests_pub_;
  std::thread request_thread_;
};
}  // namespace cnc_bridge
