// SHDR lines and the agent's device file for the machines the suite drives (shdr.h).
#include "cnc_bridge/mtconnect/shdr.h"

#include <tinyxml2.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <set>
#include <sstream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::mtconnect
{
namespace
{
const char* const kUnavailable = "UNAVAILABLE";
// Condition values: level|nativeCode|nativeSeverity|qualifier|text (cppagent 1.x).
const char* const kConditionUnavailable = "UNAVAILABLE||||";
const char* const kConditionNormal = "NORMAL||||";

// The data items of a device, as Devices.xml declares them and ShdrDevice fills them.
struct ItemSpec
{
  const char* name;
  const char* category;
  const char* type;
  const char* sub_type;  // "" none
  const char* units;     // "" none
};
const ItemSpec kAvailability{"avail", "EVENT", "AVAILABILITY", "", ""};
const ItemSpec kAxisItems[] = {
    {"Xact", "SAMPLE", "POSITION", "ACTUAL", "MILLIMETER"}, {"Xcom", "SAMPLE", "POSITION", "COMMANDED", "MILLIMETER"},
    {"Yact", "SAMPLE", "POSITION", "ACTUAL", "MILLIMETER"}, {"Ycom", "SAMPLE", "POSITION", "COMMANDED", "MILLIMETER"},
    {"Zact", "SAMPLE", "POSITION", "ACTUAL", "MILLIMETER"}, {"Zcom", "SAMPLE", "POSITION", "COMMANDED", "MILLIMETER"},
};
const ItemSpec kSpindle{"Sspeed", "SAMPLE", "ROTARY_VELOCITY", "ACTUAL", "REVOLUTION/MINUTE"};
const ItemSpec kControllerItems[] = {
    {"estop", "EVENT", "EMERGENCY_STOP", "", ""},
    {"message", "EVENT", "MESSAGE", "", ""},
    {"system", "CONDITION", "SYSTEM", "", ""},
};
const ItemSpec kPathItems[] = {
    {"mode", "EVENT", "CONTROLLER_MODE", "", ""},
    {"exec", "EVENT", "EXECUTION", "", ""},
    {"program", "EVENT", "PROGRAM", "", ""},
    {"line", "EVENT", "LINE_NUMBER", "INCREMENTAL", ""},
    {"partcount", "EVENT", "PART_COUNT", "ALL", ""},
    {"tool", "EVENT", "TOOL_NUMBER", "", ""},
    {"Frate", "SAMPLE", "PATH_FEEDRATE", "ACTUAL", "MILLIMETER/SECOND"},
};
const ItemSpec kDoor{"door_state", "EVENT", "DOOR_STATE", "", ""};

// Enough digits that the client reads back the double it was given (within 1e-12 relative).
std::string number(double value)
{
  char buffer[40];
  std::snprintf(buffer, sizeof buffer, "%.12g", value);
  return buffer;
}
std::string optionalNumber(const std::optional<double>& value, double scale)
{
  return value && std::isfinite(*value) ? number(*value * scale) : kUnavailable;
}

std::string modeValue(Mode mode)
{
  switch (mode)
  {
    case Mode::kAuto:
      return "AUTOMATIC";
    case Mode::kManual:
      return "MANUAL";
    case Mode::kMdi:
      return "MANUAL_DATA_INPUT";
    case Mode::kEdit:
      return "EDIT";
    default:
      return kUnavailable;
  }
}

// An alarm has no Execution value of its own: the program stopped, and the `system` condition
// says why (FAULT with the alarm's words).
std::string executionValue(Execution execution)
{
  switch (execution)
  {
    case Execution::kReady:
      return "READY";
    case Execution::kActive:
      return "ACTIVE";
    case Execution::kPaused:
      return "INTERRUPTED";
    case Execution::kStopped:
    case Execution::kAlarm:
      return "STOPPED";
    default:
      return kUnavailable;
  }
}

std::string estopValue(Tristate estop)
{
  return estop == Tristate::kOff ? "ARMED" : estop == Tristate::kOn ? "TRIGGERED" : kUnavailable;
}

bool isXmlName(const std::string& name)
{
  if (name.empty() || !(std::isalpha(static_cast<unsigned char>(name[0])) || name[0] == '_'))
    return false;
  return std::all_of(name.begin(), name.end(),
                     [](char c)
                     { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.'; });
}

void addItems(tinyxml2::XMLElement* parent, const std::string& device, const ItemSpec* begin, const ItemSpec* end)
{
  auto* items = parent->InsertNewChildElement("DataItems");
  for (const ItemSpec* spec = begin; spec != end; ++spec)
  {
    auto* item = items->InsertNewChildElement("DataItem");
    item->SetAttribute("category", spec->category);
    item->SetAttribute("id", (device + "_" + spec->name).c_str());
    item->SetAttribute("name", spec->name);
    item->SetAttribute("type", spec->type);
    if (*spec->sub_type)
      item->SetAttribute("subType", spec->sub_type);
    if (*spec->units)
    {
      item->SetAttribute("units", spec->units);
      item->SetAttribute("nativeUnits", spec->units);
    }
  }
}

tinyxml2::XMLElement* component(tinyxml2::XMLElement* components, const char* kind, const std::string& device,
                                const std::string& name)
{
  auto* c = components->InsertNewChildElement(kind);
  c->SetAttribute("id", (device + "_" + name).c_str());
  c->SetAttribute("name", name.c_str());
  return c;
}

void addDevice(tinyxml2::XMLElement* devices, const DeviceSpec& spec)
{
  const std::string& n = spec.name;
  auto* device = devices->InsertNewChildElement("Device");
  device->SetAttribute("id", n.c_str());
  device->SetAttribute("name", n.c_str());
  device->SetAttribute("uuid", spec.uuid.c_str());
  auto* description = device->InsertNewChildElement("Description");
  description->SetAttribute("manufacturer", "cnc_bridge");
  description->SetText(("machine " + n + " of the cell, published by mtconnect_adapter_node").c_str());
  addItems(device, n, &kAvailability, &kAvailability + 1);
  auto* components = device->InsertNewChildElement("Components");
  auto* axes_components = component(components, "Axes", n, "base")->InsertNewChildElement("Components");
  const char* axis_names[] = {"X", "Y", "Z"};
  for (size_t axis = 0; axis < 3; ++axis)
    addItems(component(axes_components, "Linear", n, axis_names[axis]), n, kAxisItems + 2 * axis,
             kAxisItems + 2 * axis + 2);
  addItems(component(axes_components, "Rotary", n, "S"), n, &kSpindle, &kSpindle + 1);
  auto* controller = component(components, "Controller", n, "controller");
  addItems(controller, n, std::begin(kControllerItems), std::end(kControllerItems));
  auto* path = component(controller->InsertNewChildElement("Components"), "Path", n, "path");
  addItems(path, n, std::begin(kPathItems), std::end(kPathItems));
  addItems(component(components, "Door", n, "door"), n, &kDoor, &kDoor + 1);
}
}  // namespace

std::string shdrKey(const std::string& device, const std::string& item)
{
  return device + ":" + item;
}

std::string shdrToken(const std::string& value)
{
  std::string out = value;
  for (char& c : out)
  {
    if (c == '|' || c == '\n' || c == '\r')
      c = ' ';
  }
  const auto first = out.find_first_not_of(" \t");
  if (first == std::string::npos)
    return "";
  return out.substr(first, out.find_last_not_of(" \t") - first + 1);
}

std::string shdrTimestamp(std::chrono::system_clock::time_point when)
{
  const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(when.time_since_epoch()).count();
  const std::time_t seconds = static_cast<std::time_t>(micros / 1000000);
  std::tm utc{};
  ::gmtime_r(&seconds, &utc);
  char buffer[48];
  const size_t n = std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%S", &utc);
  std::snprintf(buffer + n, sizeof buffer - n, ".%06lldZ", static_cast<long long>(micros % 1000000));
  return buffer;
}

std::string shdrLine(const std::string& timestamp, const std::string& tokens)
{
  return timestamp + "|" + tokens + "\n";
}

ShdrDevice::ShdrDevice(std::string name) : name_(std::move(name)) {}

std::map<std::string, std::string> ShdrDevice::valuesOf(const MachineReport& report) const
{
  std::map<std::string, std::string> values;
  const MachineView& v = report.view;
  if (!report.link_up)
  {
    // The node does not reach the machine: the agent is told it knows nothing of it.
    MachineReport up;
    up.link_up = true;
    for (const auto& [item, value] : valuesOf(up))
      values[item] = kUnavailable;
    values["system"] = kConditionUnavailable;
    values["message"] = std::string("|") + kUnavailable;
    return values;
  }
  values["avail"] = "AVAILABLE";
  values["estop"] = estopValue(v.estop);
  values["mode"] = modeValue(v.mode);
  values["exec"] = executionValue(v.execution);
  values["program"] = v.program.empty() ? kUnavailable : shdrToken(v.program);
  values["line"] = v.line == 0 ? kUnavailable : std::to_string(v.line);
  values["partcount"] = v.part_count < 0 ? kUnavailable : std::to_string(v.part_count);
  values["tool"] = v.tool < 0 ? kUnavailable : std::to_string(v.tool);
  values["door_state"] = v.door.empty() ? kUnavailable : v.door;
  const char* axes = "XYZ";
  for (size_t axis = 0; axis < 3; ++axis)
  {
    values[std::string(1, axes[axis]) + "act"] = optionalNumber(v.position[axis], 1000.0);
    values[std::string(1, axes[axis]) + "com"] = optionalNumber(v.commanded[axis], 1000.0);
  }
  values["Sspeed"] = optionalNumber(v.spindle_rpm, 1.0);
  values["Frate"] = optionalNumber(v.feed_rate, 1000.0);
  const std::string text = shdrToken(report.message);
  // A MESSAGE takes two tokens, its native code (none here) and its text.
  values["message"] = std::string("|") + (text.empty() ? kUnavailable : text);
  values["system"] = v.execution == Execution::kAlarm ? "FAULT||||" + text : kConditionNormal;
  return values;
}

std::vector<std::string> ShdrDevice::linesOf(const std::map<std::string, std::string>& values) const
{
  // Events and samples share one line. A condition takes the rest of its line, and the reference
  // agent (cppagent 1.8) reads nothing after a MESSAGE on its line: each goes on a line alone.
  std::vector<std::string> lines;
  std::string shared;
  for (const auto& [item, value] : values)
  {
    if (item == "system" || item == "message")
      continue;
    shared += (shared.empty() ? "" : "|") + shdrKey(name_, item) + "|" + value;
  }
  if (!shared.empty())
    lines.push_back(shared);
  for (const char* alone : {"message", "system"})
  {
    if (const auto it = values.find(alone); it != values.end())
      lines.push_back(shdrKey(name_, alone) + "|" + it->second);
  }
  return lines;
}

std::vector<std::string> ShdrDevice::update(const MachineReport& report)
{
  std::map<std::string, std::string> changed;
  for (auto& [item, value] : valuesOf(report))
  {
    auto it = values_.find(item);
    if (it == values_.end() || it->second != value)
    {
      changed[item] = value;
      values_[item] = value;
    }
  }
  return linesOf(changed);
}

std::vector<std::string> ShdrDevice::fullState() const
{
  if (values_.empty())
    return linesOf(valuesOf(MachineReport{}));  // nothing reported yet: all unavailable
  return linesOf(values_);
}

std::string devicesXml(const std::vector<DeviceSpec>& devices)
{
  std::set<std::string> seen;
  for (const auto& d : devices)
  {
    if (!isXmlName(d.name))
      throw ConfigError(
          "device name '" + d.name +
          "' cannot name an MTConnect device: use letters, digits, '_', '-', '.', starting with a letter or '_'");
    if (!seen.insert(d.name).second)
      throw ConfigError("device '" + d.name + "' is named twice");
  }
  if (devices.empty())
    throw ConfigError("no device to describe: give the adapter at least one machine");
  tinyxml2::XMLDocument doc;
  doc.InsertEndChild(doc.NewDeclaration(R"(xml version="1.0" encoding="UTF-8")"));
  auto* root = doc.NewElement("MTConnectDevices");
  doc.InsertEndChild(root);
  root->SetAttribute("xmlns", "urn:mtconnect.org:MTConnectDevices:1.7");
  root->SetAttribute("xmlns:m", "urn:mtconnect.org:MTConnectDevices:1.7");
  root->SetAttribute("xmlns:xsi", "http://www.w3.org/2001/XMLSchema-instance");
  root->SetAttribute(
      "xsi:schemaLocation",
      "urn:mtconnect.org:MTConnectDevices:1.7 http://schemas.mtconnect.org/schemas/MTConnectDevices_1.7.xsd");
  auto* header = root->InsertNewChildElement("Header");
  header->SetAttribute("creationTime", "2026-01-01T00:00:00Z");
  header->SetAttribute("sender", "cnc_bridge");
  header->SetAttribute("instanceId", "1");
  header->SetAttribute("bufferSize", "131072");
  header->SetAttribute("version", "1.7");
  auto* list = root->InsertNewChildElement("Devices");
  for (const auto& d : devices)
    addDevice(list, d);
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return printer.CStr();
}

std::string agentConfig(const std::vector<DeviceSpec>& devices, const std::string& devices_file,
                        const std::string& adapter_host, uint16_t adapter_port, uint16_t agent_port)
{
  if (devices.empty())
    throw ConfigError("no device to configure: give the adapter at least one machine");
  std::ostringstream out;
  out << "# cppagent 1.x configuration for the cell's SHDR adapter (mtconnect_adapter_node)\n"
      << "Devices = " << devices_file << "\n"
      << "Port = " << agent_port << "\n"
      << "SchemaVersion = 1.7\n"
      // The adapter restarts with its node: reconnect within a second (cppagent waits 10 s).
      << "ReconnectInterval = 1000\n"
      << "Adapters {\n"
      << "   cell {\n"
      << "      Host = " << adapter_host << "\n"
      << "      Port = " << adapter_port << "\n"
      << "      Device = " << devices.front().name << "\n";
  if (devices.size() > 1)
  {
    out << "      AdditionalDevices = ";
    for (size_t i = 1; i < devices.size(); ++i)
      out << (i > 1 ? ", " : "") << devices[i].name;
    out << "\n";
  }
  out << "   }\n}\n";
  return out.str();
}

std::vector<DeviceSpec> cellDevices(const std::string& cell_yaml_path)
{
  YAML::Node cell;
  try
  {
    cell = YAML::LoadFile(cell_yaml_path);
  }
  catch (const YAML::Exception& e)
  {
    throw ConfigError("cannot read the cell file " + cell_yaml_path + ": " + e.what());
  }
  const std::string cell_name = cell["cell"] ? cell["cell"].as<std::string>() : "cell";
  std::vector<DeviceSpec> devices;
  if (cell["machines"] && cell["machines"].IsSequence())
  {
    for (const auto& machine : cell["machines"])
    {
      if (!machine["name"])
        throw ConfigError(cell_yaml_path + ": a machine without a name");
      const std::string name = machine["name"].as<std::string>();
      devices.push_back({name, cell_name + "-" + name});
    }
  }
  if (devices.empty())
    throw ConfigError(cell_yaml_path + " lists no machines (machines: - name: ...)");
  return devices;
}
}  // namespace cnc_bridge::mtconnect
