// Rules that turn DPRNT lines into typed data: "a line with X, Y and Z is a probe hit",
// "the number after Z OFFSET IS is a length", "CYCLE END means the robot may unload". They come
// from a YAML file so that a cell integrator matches the macro programs of a shop without code.
// The core evaluates rules and converts device units to SI; the node only fills messages.
#pragma once

#include <cstdint>
#include <regex>
#include <string>
#include <string_view>
#include <vector>

#include "cnc_bridge/dprnt/parser.h"

namespace cnc_bridge
{
namespace dprnt
{
enum class OutputType
{
  kPoint,      ///< geometry_msgs/PointStamped, metres
  kFloat64,    ///< std_msgs/Float64, scaled to SI when units are given
  kCycleEvent  ///< cnc_bridge/CycleEvent
};

/// Values equal those of cnc_bridge/CycleEvent.msg.
enum class CycleEventKind : uint8_t
{
  kStart = 1,
  kEnd = 2,
  kPartCount = 3,
  kMarker = 4,
  kAlarm = 5
};

/// \brief What a point rule's point also is in the node's MachineState.
enum class StateField
{
  kNone,               ///< nothing: the point is only published on the rule's topics
  kPosition,           ///< the tool position the control reported (#5021.. machine position)
  kCommandedPosition,  ///< the position the program commanded (#5001.. block end position)
};

/// \brief Where a rule takes a value from: a label of the parsed line, or a capture group of its
/// regular expression (written "$1" in YAML). Empty: the first value of the line.
struct ValueSource
{
  std::string label;
  int group = -1;
  bool empty() const { return label.empty() && group < 0; }
  std::string describe() const { return group >= 0 ? "$" + std::to_string(group) : label; }
};

/// \brief One rule, as loaded from YAML (see config/dprnt_rules.yaml for the documented format).
struct Rule
{
  std::string name;  ///< unique; also names the latched topic dprnt/last/<name>
  OutputType type = OutputType::kFloat64;
  std::string topic;                     ///< relative topic name; default "dprnt/<name>"
  std::string frame;                     ///< points: "machine", "work" (tf_prefix added by the node) or any frame id
  StateField state = StateField::kNone;  ///< points in the machine frame only
  std::string regex_text;
  bool has_regex = false;
  std::regex regex;
  std::vector<std::string> labels;  ///< every one must be present in the line
  ValueSource x, y, z, value, part_count, cycle_time;
  int program_group = -1;  ///< capture group holding a program name, for cycle events
  CycleEventKind event = CycleEventKind::kMarker;
  std::string units;   ///< device unit of lengths: inch, mm, m ("program": the default); "none": unitless
  double scale = 1.0;  ///< device unit -> SI factor (inch: 0.0254 m, mm: 0.001 m)
};

/// \brief The typed result of a rule on one line; values already in SI units.
struct RuleOutput
{
  size_t rule = 0;  ///< index into RuleSet::rules()
  double x = 0, y = 0, z = 0;
  double value = 0;
  int64_t part_count = -1;
  double cycle_time = -1;  ///< s; negative when the rule has none
  std::string program;
};

/// \brief An ordered list of rules. Immutable after loading, so evaluate() is thread-safe.
class RuleSet
{
 public:
  RuleSet() = default;

  /// \brief Loads rules from YAML text: a map with a `rules:` list (or the list itself).
  /// \param default_units length unit of the programs ("inch" for G20, "mm" for G21) used by
  ///        rules that give none.
  /// \throws ConfigError naming the rule and field for anything invalid (unknown type, bad regular
  ///         expression, missing source, duplicate name).
  static RuleSet fromYaml(const std::string& text, const std::string& default_units = "inch");
  /// \brief As fromYaml(), from a file. \throws ConfigError if it cannot be read.
  static RuleSet fromFile(const std::string& path, const std::string& default_units = "inch");

  /// \brief Applies every rule to one line.
  /// \param values the line as parsed by LineParser.
  /// \param out receives one entry per matching rule (cleared first).
  /// \returns the number of rules that matched.
  size_t evaluate(std::string_view line, const std::vector<LabeledValue>& values, std::vector<RuleOutput>& out) const;

  const std::vector<Rule>& rules() const { return rules_; }

  /// \returns metres per device unit for "inch", "mm", "m"; 1 for "none".
  /// \throws ConfigError for anything else.
  static double unitScale(const std::string& units);

 private:
  std::vector<Rule> rules_;
};
}  // namespace dprnt
}  // namespace cnc_bridge
