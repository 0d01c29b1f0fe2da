// The cell's own view (docs/cell_monitor.md): may a robot enter a machine now? One answer per
// machine from the last state its node reported, with the reason when the answer is no, and the
// entry leases a robot holds, withdrawn the moment a condition breaks.
//
// This is an advisory view for the cell's software. It is not a safety PLC and never replaces the
// cell's hardware interlocks (door switches, light curtains, the robot's safety controller).
//
// Unknown is never safe: a field a node does not (yet) know, a state older than its period times a
// factor, a clock that ran backwards, all answer "no".
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace cell
{
// The values of cnc_bridge/MachineState that the rules read (same numbering as the message).
enum class Link : std::uint8_t
{
  Down = 0,
  Connecting = 1,
  Up = 2
};
enum class Execution : std::uint8_t
{
  Unknown = 0,
  Ready = 1,
  Active = 2,
  Paused = 3,
  Stopped = 4,
  Alarm = 5
};
enum class Estop : std::uint8_t
{
  Unknown = 0,
  Off = 1,
  On = 2
};
enum class Door : std::uint8_t
{
  Unknown = 0,
  Open = 1,
  Closed = 2,
  Unlatched = 3
};

/// \brief One machine's state as its node reported it. spindle_rpm is NaN when unknown.
struct MachineReport
{
  Link link = Link::Down;
  Execution execution = Execution::Unknown;
  Estop estop = Estop::Unknown;
  double spindle_rpm = 0.0;
  Door door = Door::Unknown;
};

/// \brief How one machine is judged.
struct MachineRules
{
  double state_period_s = 1.0;       ///< the node's ~state_rate period: a state is expected this often
  double stale_factor = 3.0;         ///< a state older than state_period_s * stale_factor is stale
  double settle_s = 1.0;             ///< every condition must have held this long before "safe"
  bool reports_door = false;         ///< the machine reports a door: it must be known and open
  double spindle_stopped_rpm = 0.5;  ///< |speed| below this counts as stopped

  /// \brief Empty when valid, else what to fix (names the field).
  std::string problem() const;
};

/// \brief The answer for one machine: safe, or why not.
struct Verdict
{
  bool safe = false;
  std::string reason;  ///< empty when safe
};

/// \brief Whether one report, received `age_s` ago, meets every condition (ignores settle_s).
/// Pure: the exhaustive table tests this. A negative age (a clock jump backwards) is never safe.
Verdict judgeReport(const MachineReport& report, double age_s, const MachineRules& rules);

/// \brief A lease withdrawn because a condition broke (or the machine was forgotten).
struct Withdrawal
{
  std::string machine;
  std::string robot;
  std::string reason;
};

/// \brief The rules over the cell's machines, with the entry leases. Times are seconds on a
/// monotonic clock given by the caller (the node passes steady time); a time earlier than one seen
/// before is a clock jump and makes every machine unsafe until it reports again and settles anew.
/// Not thread-safe.
class CellRules
{
 public:
  /// \brief Adds a machine (no report yet: unsafe). Throws std::invalid_argument on a duplicate
  /// name or invalid rules.
  void addMachine(const std::string& name, const MachineRules& rules);
  std::vector<std::string> machines() const;
  bool has(const std::string& name) const { return machines_.count(name) != 0; }

  /// \brief A state from the machine's node, received at `now`.
  void report(const std::string& name, const MachineReport& report, double now);

  /// \brief The machine's answer at `now` (every condition held for settle_s).
  Verdict verdict(const std::string& name, double now);

  /// \brief A robot asks to enter: granted (and leased to it) when safe and no other robot holds
  /// the machine. A robot asking again for its own lease is granted while safe.
  Verdict requestEntry(const std::string& name, const std::string& robot, double now);
  /// \brief The robot is out: its lease ends. False when it held none.
  bool release(const std::string& name, const std::string& robot);
  /// \brief The robot holding the machine, if any.
  std::optional<std::string> leaseHolder(const std::string& name) const;

  /// \brief Re-judges every leased machine at `now`; each lease whose machine is no longer safe is
  /// withdrawn and returned. Call on every report and periodically (staleness needs no report).
  std::vector<Withdrawal> withdrawBroken(double now);

 private:
  struct Machine
  {
    MachineRules rules;
    std::optional<MachineReport> last;
    double received_at = 0.0;
    std::optional<double> safe_since;  ///< when the conditions last became all met
    std::optional<std::string> lease;
  };
  Machine& machine(const std::string& name);
  void noteTime(double now);

  std::map<std::string, Machine> machines_;
  std::optional<double> latest_time_;
};

}  // namespace cell
}  // namespace cnc_bridge
