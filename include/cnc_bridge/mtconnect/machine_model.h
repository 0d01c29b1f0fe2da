// What an MTConnect device's observations say about the machine, in the suite's terms: which
// data item feeds which field (a mapping with the standard's types as its default, overridable
// because agents differ), the values converted to SI per the probe's units, cycle events from
// Execution, and the conditions that are active. ROS-free; the node copies it into messages.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/documents.h"

namespace cnc_bridge::mtconnect
{
/// \brief Field -> selectors, tried in order; the first that matches a data item of the device
/// wins. A selector is `TYPE`, `TYPE:SUBTYPE`, either with `@COMPONENT` (the component's name,
/// e.g. `POSITION:ACTUAL@X`), or `id=ID` / `name=NAME` for one data item.
using Mapping = std::map<std::string, std::vector<std::string>>;

/// \brief The fields a mapping may name.
const std::vector<std::string>& mappingFields();
/// \brief The standard's data items for each field.
Mapping defaultMapping();
/// \brief \p overrides on top of the default. \throws ConfigError for an unknown field or an
/// empty or malformed selector (the message names ~mapping).
Mapping mergeMapping(const Mapping& overrides);

enum class Mode : uint8_t  // values of cnc_bridge/MachineState.mode
{
  kUnknown = 0,
  kAuto = 1,
  kManual = 2,
  kMdi = 3,
  kEdit = 5
};
enum class Execution : uint8_t  // values of cnc_bridge/MachineState.execution
{
  kUnknown = 0,
  kReady = 1,
  kActive = 2,
  kPaused = 3,
  kStopped = 4,
  kAlarm = 5
};
enum class Tristate : uint8_t  // values of MachineState.estop
{
  kUnknown = 0,
  kOff = 1,
  kOn = 2
};

/// \brief The machine as the device's observations describe it. Unknown stays unknown.
struct MachineView
{
  std::string timestamp;  ///< of the newest observation applied
  std::optional<bool> available;
  Tristate estop = Tristate::kUnknown;
  Mode mode = Mode::kUnknown;
  Execution execution = Execution::kUnknown;
  std::string execution_text;  ///< the MTConnect value (FEED_HOLD, ...)
  std::string mode_text;
  std::string program;
  uint32_t line = 0;
  int64_t part_count = -1;
  std::array<std::optional<double>, 3> position;   ///< m, ACTUAL
  std::array<std::optional<double>, 3> commanded;  ///< m, COMMANDED
  std::optional<double> spindle_rpm;
  std::optional<double> feed_rate;  ///< m/s
  int32_t tool = -1;
  std::string door;  ///< OPEN, CLOSED, UNLATCHED; empty unknown
  bool positionValid() const { return position[0] && position[1] && position[2]; }
  bool commandedValid() const { return commanded[0] && commanded[1] && commanded[2]; }
};

enum class ConditionLevel : uint8_t  // values of cnc_bridge/MachineCondition.level
{
  kUnavailable = 0,
  kNormal = 1,
  kWarning = 2,
  kFault = 3
};

struct Condition
{
  ConditionLevel level = ConditionLevel::kUnavailable;
  std::string data_item_id;
  std::string condition_type;  ///< SYSTEM, MOTION_PROGRAM, ...
  std::string native_code;
  std::string native_severity;
  std::string qualifier;
  std::string text;
  std::string timestamp;
  uint64_t sequence = 0;
};

struct CycleEvent
{
  enum Type : uint8_t  // values of cnc_bridge/CycleEvent.event
  {
    kCycleStart = 1,
    kCycleEnd = 2,
    kPartCount = 3,
    kAlarm = 5
  };
  Type type = kCycleStart;
  std::string timestamp;
  std::string program;
  int64_t part_count = -1;
  double cycle_time = -1;  ///< s, from the agent's timestamps; negative unknown
  std::string text;
};

/// \brief What one batch of observations changed.
struct ModelChanges
{
  bool state = false;
  std::vector<CycleEvent> events;
  std::vector<Condition> conditions;  ///< condition observations, in order (the history)
};

/// \brief Applies a device's observations. Not thread-safe.
class MachineModel
{
 public:
  explicit MachineModel(Mapping mapping = defaultMapping());

  /// \brief Resolves the mapping against the device's data items (a new probe). Forgets values.
  void setDevice(const Device& device);
  /// \brief Applies observations; \p snapshot (from /current) restates everything and starts no
  /// cycle: a cycle seen only half cannot be timed.
  ModelChanges apply(const std::vector<Observation>& observations, bool snapshot);
  /// \brief Link lost or a discontinuity: values unknown until the next snapshot.
  void forget();

  const MachineView& view() const { return view_; }
  /// \returns the active (not Normal) conditions, by data item and native code.
  std::vector<Condition> activeConditions() const;
  /// \returns field -> data item id, for the fields the device has.
  const std::map<std::string, std::string>& resolved() const { return field_of_item_inverse_; }
  /// \returns the fields no data item of the device matched.
  std::vector<std::string> unmatched() const;

 private:
  void applyValue(const std::string& field, const Observation& o, ModelChanges& changes, bool snapshot);
  void applyCondition(const Observation& o, ModelChanges& changes);
  void applyExecution(const Observation& o, Execution before, ModelChanges& changes, bool snapshot);

  Mapping mapping_;
  std::map<std::string, std::vector<std::string>> field_of_item_;  // data item id -> fields (one may feed several)
  std::map<std::string, std::string> field_of_item_inverse_;       // field -> data item id
  std::map<std::string, double> scale_of_item_;                    // data item id -> factor to SI
  MachineView view_;
  bool in_cycle_ = false;
  std::string cycle_start_;                                             // timestamp
  std::map<std::string, std::map<std::string, Condition>> conditions_;  // item -> native code -> condition
};

/// \returns the factor that turns \p units into SI (MILLIMETER -> 0.001), for lengths and
/// speeds; nullopt for a unit this client does not convert.
std::optional<double> siFactor(const std::string& units);
/// \returns seconds between two ISO 8601 timestamps of an agent, or nullopt if either is not one.
std::optional<double> secondsBetween(const std::string& from, const std::string& to);
}  // namespace cnc_bridge::mtconnect
