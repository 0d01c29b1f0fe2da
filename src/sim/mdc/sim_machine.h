// The scripted Haas machine behind sim_haas_mdc: a timeline of phases (idle, a cycle with moving
// axes, a part counted, an alarm, a dropped link) that repeats, and the MDC replies such a machine
// gives at any moment. Kept in the core, without sockets, so unit tests can check it directly.
#pragma once

#include <chrono>
#include <istream>
#include <map>
#include <memory>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace mdc
{
/// \brief A Haas control as a pure function of time. Not thread-safe.
///
/// Script format (one statement per line, `#` starts a comment; see test/data/mdc/cell.mdcsim):
/// ```
/// serial 1234567               ?Q100
/// software 100.20.000.1200     ?Q101
/// model VF2D                   ?Q102
/// units inch|mm                #4006 = 20|21; positions below are in these units
/// work X Y Z                   machine coordinates of the active work zero (#5041.. = #5021.. - work):
///                              the G54 offset #5221-#5223, which ?E writes
/// var N VALUE                  initial value of macro variable #N (writable with ?E)
/// phase SECONDS key=value ...  one step of the timeline; the timeline repeats
/// ```
/// Phase keys: `mode=MEM|MDI|JOG|ZERO RET|EDIT` (underscores stand for spaces), `status=IDLE|BUSY|
/// FEED_HOLD|ALARM`, `program=O00110`, `tool=N`, `parts+=N` (counted on entering the phase),
/// `x=`, `y=`, `z=` (axis targets, reached linearly at the end of the phase), `spindle=RPM`,
/// `varN=VALUE` (macro variable #N set on entering the phase, as the running program would: e.g.
/// `var500=1` when the part is ready for a robot; a `?E` write after that wins until the next
/// phase that sets it), and the flag `drop` (every connection is closed on entering the phase).
/// Unset keys keep the previous phase's value.
class SimMachine
{
 public:
  using Clock = std::chrono::steady_clock;

  /// \brief Parses a script. \throws ConfigError naming the line.
  static SimMachine fromScript(std::istream& in, const std::string& name = "script");

  /// \brief Starts the timeline at \p start.
  void start(Clock::time_point start) { start_ = start; }

  /// \brief Which control's reply dialect to speak. NGC (the default): Q600 answers "MACRO, value"
  /// and an unknown query gets "?, <query>". Classic serial: Q600 answers "MACRO, n, value" and an
  /// unknown query gets "UNKNOWN". test/data/mdc/README.md names the sources of both.
  void setClassic(bool classic) { classic_ = classic; }

  /// \brief The reply lines (without framing) to one line from a client at \p now.
  std::string answer(const std::string& line, Clock::time_point now);

  /// \brief Writes every query answer() is given (printable characters, upper case), one per
  /// line, to \p log: what the control received, for tests that check a refused write never
  /// reached it.
  void logQueriesTo(std::shared_ptr<std::ostream> log) { query_log_ = std::move(log); }

  /// \returns true once each time the timeline enters a phase with `drop`.
  bool dropDue(Clock::time_point now);
  /// \returns true while the timeline is in a phase with `drop` (a serial line's outage lasts the
  /// whole phase).
  bool inDropPhase(Clock::time_point now) const { return phases_[stateAt(now).phase].drop; }

  /// \brief The state at \p now (for tests and the simulator's log).
  struct State
  {
    std::string mode = "MEM", status = "IDLE", program = "O00000";
    int tool = 1;
    double spindle = 0;
    long long parts = 0;
    double x = 0, y = 0, z = 0;
    size_t phase = 0;
    long long loop = 0;
    /// Variables set by the phases so far (`varN=`): value, and when (s since start()) the phase
    /// that set it began.
    std::map<int, std::pair<double, double>> variables;
  };
  State stateAt(Clock::time_point now) const;

  double timelineSeconds() const;
  /// \returns true when the script's positions are inches (`units inch`), false for millimetres.
  bool inch() const { return inch_; }

  /// \brief Lengths in s of the last and the one before last cycle (a run of BUSY / FEED_HOLD
  /// phases) that ended by \p now: Q303 LAST CYCLE and Q304 PREV CYCLE. 0 when none yet.
  std::pair<double, double> lastCycles(Clock::time_point now) const;

 private:
  std::shared_ptr<std::ostream> query_log_;
  struct Phase
  {
    double seconds = 1.0;
    std::map<std::string, std::string> set;
    long long parts_increment = 0;
    std::optional<double> x, y, z;
    std::map<int, double> variables;  ///< varN=VALUE
    bool drop = false;
    size_t line = 0;
  };
  struct ScriptLine;  // the script line being read, for errors (sim_machine.cpp)

  // Reading a script (fromScript): one statement, a phase, one key=value of a phase.
  void readStatement(const std::string& keyword, std::istream& words, const ScriptLine& script);
  static Phase readPhase(std::istream& words, const ScriptLine& script);
  static void setPhaseKey(Phase& phase, const std::string& key, const std::string& value, const ScriptLine& script);
  // Answering (answer): a ?E write, a Q600 macro variable read.
  std::string answerWrite(const std::string& command, Clock::time_point now);
  std::string answerMacro(const std::optional<double>& argument, const State& s, const std::string& unknown) const;

  std::string serial_ = "1234567", software_ = "100.20.000.1200", model_ = "VF2D";
  bool inch_ = true;
  bool classic_ = false;
  double work_[3] = {0, 0, 0};
  std::map<int, double> variables_;   ///< initial values (`var`) and `?E` writes
  std::map<int, double> written_at_;  ///< when (s since start()) each `?E` write came
  std::vector<Phase> phases_;
  Clock::time_point start_ = Clock::now();
  std::optional<std::pair<long long, size_t>> last_drop_;
};
}  // namespace mdc
}  // namespace cnc_bridge
