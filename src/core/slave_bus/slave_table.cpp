// The configured slaves of a bus (see slave_table.h).
#include "cnc_bridge/slave_bus/slave_table.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <set>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace slave_bus
{
Role parseRole(const std::string& text)
{
  if (text == "x" || text == "axis_x")
    return Role::kAxisX;
  if (text == "y" || text == "axis_y")
    return Role::kAxisY;
  if (text == "z" || text == "axis_z")
    return Role::kAxisZ;
  if (text == "tool")
    return Role::kTool;
  if (text == "generic")
    return Role::kGeneric;
  throw ConfigError("role '" + text + "' is not one of x, y, z, tool, generic");
}

bool isAxis(Role role)
{
  return role == Role::kAxisX || role == Role::kAxisY || role == Role::kAxisZ;
}

bool startsMotion(Role role)
{
  return role != Role::kGeneric;
}

namespace
{
// A ROS graph name part: a letter, then letters, digits and underscores (the slave's topics are
// slaves/<name>/command and slaves/<name>/response).
bool validName(const std::string& name)
{
  return !name.empty() && std::isalpha(static_cast<unsigned char>(name[0])) &&
         std::all_of(name.begin(), name.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; });
}
}  // namespace

SlaveTable::SlaveTable(std::vector<SlaveConfig> slaves, size_t bus_size, WireFormat wire,
                       const std::string& slaves_name, const std::string& bus_size_name)
    : slaves_(std::move(slaves)), wire_(wire)
{
  if (slaves_.empty())
  {
    throw ConfigError(slaves_name + " must be a non-empty list");
  }
  std::set<std::string> names;
  std::set<Role> axes;
  size_t highest = 0;
  for (size_t i = 0; i < slaves_.size(); ++i)
  {
    const SlaveConfig& slave = slaves_[i];
    const std::string entry = slaves_name + "[" + std::to_string(i) + "]";
    if (slave.address < 1 || slave.address > kMaxSlaves || !by_address_.emplace(slave.address, i).second)
    {
      throw ConfigError(entry + ".address must be unique and in 1.." + std::to_string(kMaxSlaves));
    }
    if (!validName(slave.name) || !names.insert(slave.name).second)
    {
      throw ConfigError(entry + ".name '" + slave.name +
                        "' must be unique and a valid topic name part (a letter, then letters, digits, '_')");
    }
    if (!(std::isfinite(slave.scale) && slave.scale != 0.0))
    {
      throw ConfigError(entry + ".scale must be a finite, non-zero number of device units per metre");
    }
    if (isAxis(slave.role) && !axes.insert(slave.role).second)
    {
      throw ConfigError(entry + ": a second slave for the same axis");
    }
    highest = std::max<size_t>(highest, slave.address);
  }
  axis_count_ = axes.size();
  bus_size_ = bus_size == 0 ? highest : bus_size;
  if (bus_size_ < highest || bus_size_ > kMaxSlaves)
  {
    throw ConfigError(bus_size_name + " must be between the highest slave address (" + std::to_string(highest) +
                      ") and " + std::to_string(kMaxSlaves) + ", not " + std::to_string(bus_size_));
  }
}

int SlaveTable::indexOf(uint8_t address) const
{
  const auto found = by_address_.find(address);
  return found == by_address_.end() ? -1 : static_cast<int>(found->second);
}

bool SlaveTable::startsMotion(uint8_t address) const
{
  const int index = indexOf(address);
  return index < 0 || slave_bus::startsMotion(slaves_[static_cast<size_t>(index)].role);
}

std::vector<uint8_t> SlaveTable::commandPayload(size_t index, const std::vector<double>& values,
                                                const std::vector<uint8_t>& data) const
{
  const SlaveConfig& slave = slaves_.at(index);
  if (values.empty() == data.empty())
  {
    throw ProtocolError("give either values or data");
  }
  if (!data.empty())
  {
    if (data.size() > wire_.max_data)
    {
      throw ProtocolError(std::to_string(data.size()) + " bytes: " + payloadLimit());
    }
    return data;
  }
  std::vector<int32_t> encoded;
  if (isAxis(slave.role))
  {
    if (values.size() != 1)
    {
      throw ProtocolError("an axis takes one value, its position in m");
    }
    // m -> device units (steps, pulses, 1/100 mm...: whatever the scale says per metre). Exact or
    // refused: a position between two device units is not rounded to one of them.
    const double units = values[0] * slave.scale;
    const double device = std::round(units);
    if (!std::isfinite(device) || device < minValue(slave.encoding) || device > maxValue(slave.encoding))
    {
      throw ProtocolError("position " + std::to_string(values[0]) + " m is " + std::to_string(units) +
                          " device units, outside what " + toString(slave.encoding) + " carries");
    }
    // 1e-6 of a unit: the binary fraction of a metre value of whole units (0.0123 m * 1000).
    if (std::fabs(units - device) > 1e-6)
    {
      throw ProtocolError("position " + std::to_string(values[0]) + " m is " + std::to_string(units) +
                          " device units, not a whole unit (scale " + std::to_string(slave.scale) +
                          " per m): give a multiple of " + std::to_string(1.0 / slave.scale) + " m");
    }
    encoded.push_back(static_cast<int32_t>(device));
  }
  else
  {
    for (const double value : values)
    {
      if (!std::isfinite(value) || std::fabs(value - std::round(value)) > 1e-9 || std::fabs(value) > 1e9)
      {
        throw ProtocolError("value " + std::to_string(value) + " is not an integer");
      }
      encoded.push_back(static_cast<int32_t>(std::round(value)));
    }
  }
  auto payload = encodeValues(encoded, slave.encoding);
  if (payload.size() > wire_.max_data)
  {
    throw ProtocolError("too many values for one payload: " + payloadLimit());
  }
  return payload;
}

StepPayloads SlaveTable::framePayloads(const std::vector<std::pair<uint8_t, std::vector<uint8_t>>>& payloads) const
{
  StepPayloads step(bus_size_);
  std::set<uint8_t> seen;
  for (const auto& [address, data] : payloads)
  {
    const std::string at = "address " + std::to_string(address);
    if (address < 1 || address > bus_size_)
    {
      throw ProtocolError(at + " is outside the bus (1.." + std::to_string(bus_size_) + ")");
    }
    if (!seen.insert(address).second)
    {
      throw ProtocolError("two payloads for " + at);
    }
    if (data.size() > wire_.max_data)
    {
      throw ProtocolError("payload for " + at + " has " + std::to_string(data.size()) + " bytes: " + payloadLimit());
    }
    step[address - 1] = data;
  }
  return step;
}

std::vector<double> SlaveTable::replyValues(size_t index, const std::vector<uint8_t>& payload) const
{
  const SlaveConfig& slave = slaves_.at(index);
  std::vector<double> values;
  for (const int32_t value : decodeValues(payload, slave.encoding))
  {
    // Axis answers are device units: back to metres with the same scale.
    values.push_back(isAxis(slave.role) ? value / slave.scale : value);
  }
  return values;
}

std::string SlaveTable::payloadLimit() const
{
  return "one I2C frame of the master carries at most " + std::to_string(wire_.max_data) + " bytes (~max_payload" +
         (wire_.crc == WireCrc::kLibrary && wire_.max_data == WireFormat::kLibraryMaxData
              ? "; the ESP32_I2C_Slave library's 128-byte buffers)"
              : ")");
}
}  // namespace slave_bus
}  // namespace cnc_bridge
