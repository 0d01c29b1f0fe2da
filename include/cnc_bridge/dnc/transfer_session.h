// dnc_node's transfers without ROS (docs/dnc_node.md): one session owns the control's serial link
// (opened per transfer or kept open; the port lock held while a transfer runs, so a status poller
// on the same line stays quiet), runs one transfer at a time (a second is refused with what holds
// the port), checks each against the transfer core's rules (the files it may touch, the protected
// programs, the motion switch for a drip-feed), dispatches it to a protocol handler by name
// (XModem built in; drip and backup in dnc/drip_protocols.h), counts it, archives what moved and
// tells a listener what to show. With requests enabled, a thread listens on the idle port for the
// request programs the control punches and serves them (transfer_session_requests.cpp). The node
// maps the listener's calls and the outcomes to its topics, action, services and diagnostics.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/dnc/dnc_settings.h"
#include "cnc_bridge/dnc/program_requests.h"
#include "cnc_bridge/dnc/transfer_gate.h"
#include "cnc_bridge/dnc/transfer_rules.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/transport/link_factory.h"

namespace cnc_bridge::dnc
{
constexpr const char* kDirectionSend = "send";  ///< as Transfer.action's DIRECTION_SEND
constexpr const char* kDirectionReceive = "receive";

/// \brief A transfer asked for (a ~transfer goal, a service call, a served request).
struct TransferRequest
{
  std::string direction;         ///< kDirectionSend or kDirectionReceive
  std::string protocol;          ///< "" for the default (~xmodem_mode)
  std::string file;              ///< inside the program directory
  uint32_t start_line = 0;       ///< drip: restart at this 1-based line (0: from the start)
  std::string start_block;       ///< drip: restart at this sequence number ("" unused)
  std::string restart_preamble;  ///< drip: modal blocks before the restart point ("" computed)
};

/// \brief How far a transfer is (Transfer.action's feedback).
struct TransferProgress
{
  uint64_t bytes = 0, total = 0;
  uint32_t block = 0, retries = 0, line = 0;
  std::string block_number;
  float percent = 0;
  bool held = false, paused = false;
};
using ProgressFunction = std::function<void(const TransferProgress&)>;

/// \brief How a transfer ended (Transfer.action's result).
struct TransferOutcome
{
  bool success = false;
  std::string message;
  uint64_t bytes = 0;
  uint32_t blocks = 0, retries = 0, stopped_at_line = 0;
  std::string stopped_at_block;
  bool cancelled = false;  ///< it ended because it was cancelled
};

/// \brief One transfer as a protocol handler sees it.
struct TransferJob
{
  TransferRequest request;  ///< as requested (protocol already defaulted)
  std::string path;         ///< request.file resolved inside the program directory
  bool send = true;
  /// For a send: checks the bytes read to be sent (the protected range), before the first goes out.
  std::function<void(const std::string& contents)> check_contents;
};

/// \brief Moves one file over \p link. Reports progress through \p progress, stops with
/// CancelledError (or a result that says so) when \p cancel is set (the link is interrupted too),
/// and returns the outcome or throws a cnc_bridge::Error whose message becomes the outcome's.
using ProtocolHandler = std::function<TransferOutcome(
    Transport& link, const TransferJob& job, const ProgressFunction& progress, const std::atomic<bool>& cancel)>;

/// \brief What the machine is doing, as the node's state shows it.
enum class Execution
{
  kReady,
  kActive,
  kPaused,
  kStopped
};

/// \brief A change of the state shown: only the fields set change.
struct StateChange
{
  std::optional<Execution> execution;
  std::optional<std::string> program;
  std::optional<uint32_t> block;
  std::optional<std::string> message;
};

/// \brief A program request punched by the control and what became of it (ProgramRequestEvent).
struct RequestEvent
{
  std::string request;  ///< LOAD, SEND or SAVE; "" when none was recognised
  uint32_t number = 0;
  std::string program;
  std::string outcome;
  bool success = false;
};

/// \brief What the session tells the node. Called from the thread running the transfer or the
/// request listener; must not call back into the session.
class TransferListener
{
 public:
  virtual ~TransferListener() = default;
  virtual void onLink(LinkState /*state*/, const std::string& /*message*/) {}
  virtual void onState(const StateChange& /*change*/) {}
  virtual void onRequest(const RequestEvent& /*event*/) {}
};

/// \brief The session's own parts besides the settings.
struct SessionParts
{
  TransferListener* listener = nullptr;  ///< must outlive the session
  const SafetySwitch* motion = nullptr;  ///< gates drip-feeds; must outlive the session
  std::string machine;                   ///< named in the archive's versions and request events
  std::string cancel_topic;              ///< how to cancel a goal, named in a busy refusal
  LinkFactory open_link;                 ///< empty: linkFactory(settings.link)
};

/// \brief Thread-safe: transfers, cancels and the request listener may come from any thread.
class TransferSession
{
 public:
  /// Creates the program directory if missing and registers the XModem protocols.
  /// \throws ConfigError for a bad protected range or name pattern.
  TransferSession(const TransferSettings& settings, const RequestSettings& requests, const SessionParts& parts);
  /// Stops the request listener and cancels a running transfer.
  ~TransferSession();
  TransferSession(const TransferSession&) = delete;
  TransferSession& operator=(const TransferSession&) = delete;

  /// \brief Makes \p protocol available to transfers (before start()).
  void registerProtocol(const std::string& protocol, ProtocolHandler handler);
  /// \brief Opens a kept-open port (a failure is logged and retried at the next transfer) and
  /// starts the request listener when requests are enabled.
  void start();
  /// \brief Stops the request listener for good and cancels a running transfer (the node's end).
  void stop();

  /// \brief Runs a transfer start to end (a service call): refused if one runs, else as runReserved().
  TransferOutcome run(TransferRequest request, const ProgressFunction& progress);
  /// \brief Takes the port for one transfer, \p what (named in the refusal of another); false (and
  /// counted as refused) if one is running.
  bool tryReserve(const std::string& what);
  void release() { gate_.release(); }
  /// \brief Runs a transfer the caller has reserved the port for (tryReserve()).
  TransferOutcome runReserved(TransferRequest request, const ProgressFunction& progress);
  /// \brief The refusal of a transfer asked for while another runs.
  std::string busyMessage() const;
  /// \brief Stops the running transfer (it ends cancelled).
  void cancelRunning();
  bool cancelRequested() const { return gate_.cancelFlag(); }

  const ProgramDirectory& programs() const { return *programs_; }
  const std::string& defaultProtocol() const { return settings_.default_protocol; }
  const std::string& device() const { return settings_.link.serial.device; }
  bool requestsEnabled() const { return requests_.enabled; }
  TransferTotals totals() const { return counters_.totals(); }

 private:
  std::string checkJob(TransferJob& job);
  TransferOutcome runOnPort(const ProtocolHandler& handler, const TransferJob& job, const std::string& transfer_message,
                            const ProgressFunction& progress);
  void endTransfer(const TransferJob& job, const TransferOutcome& outcome);
  void archiveProgram(const TransferJob& job);
  TransferOutcome runXmodem(Transport& link, const TransferJob& job, const ProgressFunction& progress,
                            const std::atomic<bool>& cancel);
  Transport& openLink();
  void closeLink();
  void state(const StateChange& change) { listener_.onState(change); }

  // Program requests (transfer_session_requests.cpp).
  void requestWorker();
  void requestError(const std::string& error, bool reserved);
  std::optional<Punch> listenForPunch(bool& reserved);
  void servePunch(const Punch& punch);
  void keepUnrequested(const Punch& punch);
  std::string saveNextPunch(const std::string& name, bool& success);
  std::string answerRefusal(const Punch& punch, const std::string& shown);
  void reportRequestInTransfer(const TransferJob& job);
  void publishRequest(const RequestEvent& event);

  const TransferSettings settings_;
  const RequestSettings requests_;
  TransferListener& listener_;
  const SafetySwitch& motion_;
  const std::string machine_;
  const std::string cancel_topic_;
  bool keep_open_;                ///< ~keep_open, or requests enabled
  std::string request_protocol_;  ///< the protocol a LOAD is answered by

  std::unique_ptr<ProgramDirectory> programs_;
  programs::ProtectedRange protected_;  ///< refused on send unless allowed
  programs::NamePattern name_pattern_;
  programs::ProgramArchive archive_;  ///< every program sent or received, versioned
  TransferFiles files_;               ///< what a transfer may touch, and the archiving
  std::map<std::string, ProtocolHandler> protocols_;

  LinkFactory open_link_;  ///< the only way the link is opened (openLink())
  PortLock port_lock_;
  /// One transfer at a time (an admitted goal holds it until its result goes out), the request
  /// listener only while none runs; its cancel flag stops the running transfer.
  TransferGate gate_;
  std::mutex link_mutex_;  ///< guards link_ for cancelRunning()
  std::unique_ptr<Transport> link_;
  uint64_t link_generation_ = 0;  ///< counts the links opened (guarded by link_mutex_)
  TransferCounters counters_;

  std::unique_ptr<RequestListener> listener_port_;
  uint64_t listener_generation_ = 0;  ///< link_generation_ of the link listener_port_ was made for
  std::chrono::steady_clock::time_point last_request_error_{};  ///< request errors logged once a minute
  std::thread request_thread_;
};
}  // namespace cnc_bridge::dnc
