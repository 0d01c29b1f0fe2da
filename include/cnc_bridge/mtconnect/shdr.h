// MTConnect out: the machines the suite drives described to an MTConnect agent. An SHDR adapter
// (the agent connects to it over TCP and reads `|`-separated timestamped lines) publishes each
// machine as one device of the agent; the device's data items are the ones generated here into
// the agent's Devices.xml, and the lines are what changed since the last ones. ROS-free: the
// adapter node fills a MachineView per machine from its MachineState.
#pragma once

#include <chrono>
#include <map>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/machine_model.h"

namespace cnc_bridge::mtconnect
{
/// \brief One machine as the adapter publishes it: the view (the same struct the client fills, so
/// that a round trip compares field for field), whether its node reaches it, and its last alarm.
struct MachineReport
{
  bool link_up = false;  ///< false: every data item UNAVAILABLE (the agent knows nothing)
  MachineView view;      ///< positions m, feed m/s, spindle rev/min (as the client reads them)
  std::string message;   ///< the alarm's words with execution kAlarm; else an event's (MESSAGE)
};

/// \brief A device of the cell: its name (the agent's device name, a machine's `name` in
/// config/cell.yaml) and the uuid the agent reports.
struct DeviceSpec
{
  std::string name;
  std::string uuid;
};

/// \brief The SHDR key of data item \p item of device \p device (`device:item`): one adapter
/// serves several devices (cppagent's Device + AdditionalDevices).
std::string shdrKey(const std::string& device, const std::string& item);

/// \brief The data item values of one device, and what changed since the last lines made.
class ShdrDevice
{
 public:
  explicit ShdrDevice(std::string name);

  const std::string& name() const { return name_; }
  /// \brief Takes the machine's new report. \returns the lines (without timestamp and newline)
  /// for the data items whose value changed; the first report gives every item.
  std::vector<std::string> update(const MachineReport& report);
  /// \returns every data item's value, as lines: what a newly connected agent is sent first.
  std::vector<std::string> fullState() const;

 private:
  std::map<std::string, std::string> valuesOf(const MachineReport& report) const;
  std::vector<std::string> linesOf(const std::map<std::string, std::string>& values) const;

  std::string name_;
  std::map<std::string, std::string> values_;  // item -> value (conditions: level|code|...|text)
};

/// \brief The text \p value as one SHDR token: `|` and line ends (which would cut the line into
/// other tokens or lines) become spaces; leading and trailing spaces are dropped (the agent trims
/// them).
std::string shdrToken(const std::string& value);
/// \returns \p when as the agent's timestamps are written (UTC, microseconds, `Z`).
std::string shdrTimestamp(std::chrono::system_clock::time_point when);

/// \brief An SHDR line: `timestamp|tokens` followed by a newline.
std::string shdrLine(const std::string& timestamp, const std::string& tokens);

/// \brief Devices.xml for the agent (MTConnect 1.7): one device per machine with the data items
/// ShdrDevice writes. \throws ConfigError for a name that is not an XML name, or twice.
std::string devicesXml(const std::vector<DeviceSpec>& devices);
/// \brief The agent.cfg lines that connect cppagent to this adapter for these devices (the first
/// as `Device`, the others as `AdditionalDevices`), with its Devices.xml at \p devices_file.
std::string agentConfig(const std::vector<DeviceSpec>& devices, const std::string& devices_file,
                        const std::string& adapter_host, uint16_t adapter_port, uint16_t agent_port);
/// \brief The machines of a cell file (config/cell.yaml: `cell` and `machines[].name`), uuids
/// `<cell>-<name>`. \throws ConfigError naming the file for a file without machines.
std::vector<DeviceSpec> cellDevices(const std::string& cell_yaml_path);
}  // namespace cnc_bridge::mtconnect
