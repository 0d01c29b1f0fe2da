// What a host learns from polling a Haas control over MDC, and how it polls: a scheduler that runs
// each query at its own period, a monitor that folds replies (ours and those meant for another MDC
// client) into one machine status and detects cycle start/end and part-count events, and a poller
// that drives both over an MdcClient while respecting the shared serial-port lock of a DNC transfer.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/mdc/mdc_client.h"
#include "cnc_bridge/transport/backoff.h"

namespace cnc_bridge
{
namespace mdc
{
using Clock = std::chrono::steady_clock;

/// \brief Runs each query at its own period. Queries due at the same time go in the order they
/// were added. Not thread-safe.
class QueryScheduler
{
 public:
  /// \brief Period of a query sent once per connection (serial number, model).
  static constexpr Milliseconds kOnce{-1};

  /// \param period time between two sends (0: as often as possible), or kOnce.
  void add(const Query& query, Milliseconds period);
  /// \brief Everything due at \p now again, once-only queries included (after a reconnect).
  void reset(Clock::time_point now);
  /// \returns the query due first and when; nullopt when nothing is left.
  std::optional<std::pair<Query, Clock::time_point>> next() const;
  /// \brief The query next() returned was answered (or rejected) at \p now: schedule its next run
  /// one period after its due time, or at \p now if that is already past (no bursts after a stall).
  /// A once-only query is finished.
  void done(Clock::time_point now);
  /// \brief The query next() returned went unanswered at \p now: a periodic one is scheduled as by
  /// done(); a once-only one is not finished but tried again at \p now + \p retry_after.
  void unanswered(Clock::time_point now, Milliseconds retry_after);
  /// \brief The query next() returned was rejected by the control ("?, ?Q100") at \p now: as done(),
  /// except that a once-only query rejected for the first time since reset() is asked again at
  /// \p now + \p retry_after (the first ?Q100 on a new connection may be refused).
  void rejected(Clock::time_point now, Milliseconds retry_after);
  size_t size() const { return slots_.size(); }

  /// \brief The queries and their periods, in the order added.
  std::vector<std::pair<Query, Milliseconds>> plan() const;

 private:
  struct Slot
  {
    Query query;
    Milliseconds period;
    Clock::time_point due;
    bool finished = false;
    unsigned rejections = 0;  ///< since reset()
  };
  Slot* current();
  std::vector<Slot> slots_;
};

/// \brief Linear unit of the positions the control reports, from G20/G21 (macro #4006).
enum class Units
{
  kUnknown,
  kInch,
  kMillimetre
};

/// \brief Everything known about the machine. Plain data.
struct MachineStatus
{
  std::string serial_number, software_version, model;
  std::string mode_text;  ///< Q104 as sent, "(MEM)"
  Mode mode = Mode::kUnknown;
  std::string status_text;  ///< Q500 status as sent, "IDLE"
  Execution execution = Execution::kUnknown;
  std::string program;
  std::optional<int64_t> parts;
  std::optional<int64_t> tool;
  std::optional<int64_t> tool_changes;
  std::optional<int64_t> m30_counter1, m30_counter2;
  std::optional<double> last_cycle_s, previous_cycle_s, power_on_s, motion_s;
  std::map<int, double> variables;  ///< Q600 values by variable number, read on this connection
  /// Why the last poll of a variable gave no value ("no reply within 1000 ms", the control's
  /// rejection, a malformed reply), by variable number; gone once a value arrives.
  std::map<int, std::string> variable_errors;
  Units units = Units::kUnknown;  ///< from #4006 when it is polled
  /// Work zero X Y Z in machine coordinates (device units), see MdcMonitor::setWorkOffsetAxes().
  std::optional<double> work_offset[3];
  uint64_t updates = 0;  ///< replies folded in
};

/// \brief A cycle or part-count event (values as cnc_bridge/CycleEvent).
struct CycleEventData
{
  enum Type : uint8_t
  {
    kCycleStart = 1,
    kCycleEnd = 2,
    kPartCount = 3,
    kAlarm = 5
  };
  Type type = kCycleStart;
  std::string program;
  int64_t part_count = -1;
  double cycle_time = -1;  ///< s; negative when unknown (the cycle began before we connected)
  std::string text;
};

/// \brief Folds replies into a MachineStatus and finds cycle events. Not thread-safe.
///
/// Cycle rules (Q500): a change from not running to BUSY or FEED HOLD starts a cycle; back to IDLE
/// (or a stop) ends it, carrying the part count the control reports then and the time since the
/// start; ALARM during a cycle ends it with an alarm event; a part count that rises while no cycle
/// was seen (a cycle shorter than the poll period) is a part-count event. The first status after
/// start-up gives no event: we do not know what came before.
class MdcMonitor
{
 public:
  /// \brief Variables of machine and work position per axis (Haas #5021/#5041, #5022/#5042,
  /// #5023/#5043). The work offset of an axis is machine - work position, but the two are read one
  /// after the other: it is taken only when the machine position read before and after the work
  /// position is the same (the axis stood still in between), so motion never leaks into it.
  void setWorkOffsetAxes(const std::vector<std::pair<int, int>>& machine_work);

  /// \brief Applies one reply received at \p now.
  /// \returns the events it caused (usually none).
  std::vector<CycleEventData> apply(const Reply& reply, Clock::time_point now);
  const MachineStatus& status() const { return status_; }
  bool inCycle() const { return in_cycle_; }

  /// \brief A poll of \p variable gave no value, for the reason \p why (kept until a value arrives).
  void variableFailed(int variable, const std::string& why) { status_.variable_errors[variable] = why; }
  /// \brief Forgets the variables' values and errors (a new connection: only what it reads counts).
  void forgetVariables()
  {
    status_.variables.clear();
    status_.variable_errors.clear();
  }

 private:
  std::vector<CycleEventData> applyProgramStatus(const ProgramStatus& ps, Clock::time_point now);

  struct AxisPair
  {
    int machine = 0, work = 0;
    std::optional<double> last_machine, work_since;
  };

  MachineStatus status_;
  std::vector<AxisPair> axes_;
  bool seen_status_ = false;
  bool in_cycle_ = false;
  std::optional<Clock::time_point> cycle_start_;
};

/// \brief Decides when the values of watched macro variables are published (the `variables`
/// topic of haas_mdc_node): once every one of them was polled on the connection (a value, or an
/// error: then NaN), and after that only when a value changes. Not thread-safe.
class VariableWatch
{
 public:
  explicit VariableWatch(std::vector<int> numbers) : numbers_(std::move(numbers)) {}
  const std::vector<int>& numbers() const { return numbers_; }

  /// \returns the values in the order of numbers() (NaN: no value, see
  /// MachineStatus::variable_errors) when they are to be published, else nullopt.
  std::optional<std::vector<double>> update(const MachineStatus& status);
  /// \brief The link is down: nothing is known. \returns all NaN once, if values were published
  /// since the last loss; the next connection's first complete poll is published again.
  std::optional<std::vector<double>> linkLost();
  /// \returns "#500: no reply within 1000 ms; #9999: ..." for the watched variables that have an
  /// error in \p status; empty when none has.
  std::string errors(const MachineStatus& status) const;

 private:
  std::vector<int> numbers_;
  std::optional<std::vector<double>> published_;  ///< the values last published
};

/// \brief What to poll and how often.
struct PollPlan
{
  Milliseconds status_period{250};     ///< Q500 and Q104
  Milliseconds variables_period{250};  ///< each Q600 variable
  Milliseconds counters_period{2000};  ///< Q201 tool, Q303/Q304 cycle times, Q402 M30 counter, Q200
  std::vector<int> variables;          ///< Q600 list (positions, spindle, counters, #100s)
  std::vector<int> slow_variables;     ///< Q600 list polled at counters_period (#4006 units)
  bool identity = true;                ///< Q100, Q101, Q102 once per connection
  /// Per-query periods that override the group periods above; a query not in the plan is added
  /// (e.g. Q300 power-on time), a period of 0 removes it from the plan.
  std::vector<std::pair<Query, Milliseconds>> query_periods;
  /// When a cycle ends, ask the control for its last cycle time (Q303) at once and put it in the
  /// cycle-end event; the time measured between polls stays the fallback.
  bool cycle_time_from_control = true;
  /// Queries left unanswered in a row before the link is declared dead (a serial control switched
  /// off, a half-open TCP connection); the poller then ends with LinkError so it is reopened.
  unsigned max_unanswered = 5;

  /// \brief The scheduler for this plan.
  QueryScheduler scheduler() const;
};

/// \brief Reads a key of a per-query period table: "Q500", "?Q500", "Q600 5021" (a read-only query).
/// \throws ConfigError naming \p key when it is not one.
Query parseQueryKey(const std::string& key);

/// \brief Polls over one connection until stopped or the link fails. Thread-safe as documented
/// per method: run() in one thread; withClient() from any other.
class MdcPoller
{
 public:
  /// \brief Called (under the client lock) after each reply is folded in, with the events found.
  using UpdateListener = std::function<void(const MachineStatus&, const std::vector<CycleEventData>&)>;

  /// \brief Called with the link, the port lock held, before the first query after another process
  /// (a DNC transfer) used the serial line: the line's settings may have been changed meanwhile.
  using PortRegainedHook = std::function<void(Transport&)>;

  /// \param port_lock if set, it is held for each query (PortLock::tryLockForQuery()), and polls
  ///        wait while another process holds it or waits for it (a DNC transfer on the same serial
  ///        port: polling a Classic control then can freeze it, and a query would mix with the
  ///        transfer's bytes).
  MdcPoller(PollPlan plan, Milliseconds reply_timeout, PortLock* port_lock = nullptr);

  void setPortRegainedHook(PortRegainedHook hook) { port_regained_ = std::move(hook); }

  /// \brief See MdcMonitor::setWorkOffsetAxes(). Call before run().
  void setWorkOffsetAxes(const std::vector<std::pair<int, int>>& machine_work);

  void setListener(UpdateListener listener) { listener_ = std::move(listener); }

  /// \brief Shares a Classic control's port with its DPRNT output (MdcClient::setTextListener()):
  /// \p listener gets every line that is no reply, in the order read, in the poller's thread. The
  /// poller then reads the line between polls too (the port lock held for each 50 ms look), so a
  /// line is passed on as it comes, and a DNC transfer finds no DPRNT line waiting. Call before run().
  void setTextListener(MdcClient::TextListener listener) { text_listener_ = std::move(listener); }

  /// \brief Polls over \p transport until \p stop is stopped (returns) or the link fails (throws
  /// LinkError / CancelledError). A query left unanswered is counted and the poll goes on, up to
  /// PollPlan::max_unanswered in a row (then LinkError).
  void run(Transport& transport, StopSignal& stop);

  /// \brief Runs \p action with the live client, between two polls.
  /// \throws LinkError when there is no connection.
  void withClient(const std::function<void(MdcClient&)>& action);

  /// \brief A copy of the status and counters. Thread-safe.
  MachineStatus status() const;
  ClientStats stats() const;
  /// \brief Times a due poll waited (50 ms each) because another process held or wanted the port.
  uint64_t skippedForPortLock() const;
  /// \brief Times the port came back after another process had used it (settings reapplied).
  uint64_t portRegained() const;
  uint64_t polls() const;

 private:
  class PortUse;
  void notify(const Reply& reply);
  /// Records why a Q600 poll gave no value (with mutex_ held). \returns false for other queries.
  bool noteVariableFailure(const Query& query, const std::string& why);
  /// Takes the port lock for one use (with mutex_ held). \returns false if it is busy.
  bool takePort(MdcClient& client);
  /// Asks for the control's cycle time for cycle ends held back by notify(), then delivers them.
  void deliverHeldEvents(MdcClient& client);
  /// A new connection's client: stale values forgotten, cycle ends held for their measured time.
  void attach(MdcClient& client);
  /// Waits \p wait for the next poll, reading the line meanwhile when it carries text. \returns
  /// true when stopped.
  bool waitForPoll(MdcClient& client, Milliseconds wait, StopSignal& stop);

  PollPlan plan_;
  Milliseconds reply_timeout_;
  PortLock* port_lock_;
  UpdateListener listener_;
  PortRegainedHook port_regained_;
  MdcClient::TextListener text_listener_;

  mutable std::mutex mutex_;  // guards everything below, and all use of client_
  MdcClient* client_ = nullptr;
  MdcMonitor monitor_;
  ClientStats stats_;  // of past connections plus the live one
  ClientStats base_stats_;
  uint64_t skipped_ = 0;
  uint64_t regained_ = 0;
  uint64_t polls_ = 0;
  std::optional<uint64_t> port_generation_;  // of the port lock when last held, this connection
  bool hold_cycle_ends_ = false;             // a client can ask Q303 before the event goes out
  std::vector<CycleEventData> held_events_;
};
}  // namespace mdc
}  // namespace cnc_bridge
