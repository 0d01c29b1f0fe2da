// The slaves of one bus as the cell configures them (address, name, role, value encoding, scale),
// and what follows from them: which payloads move or cut, a command's payload from values in SI
// units, a reply's values back in SI units, and the checks of an explicit step frame.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/slave_bus/array_protocol.h"
#include "cnc_bridge/slave_bus/value_codec.h"
#include "cnc_bridge/slave_bus/wire_packer.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief What a slave is to the machine.
enum class Role
{
  kAxisX,
  kAxisY,
  kAxisZ,
  kTool,
  kGeneric
};

/// \brief "x"/"axis_x", "y"/"axis_y", "z"/"axis_z", "tool", "generic". \throws ConfigError.
Role parseRole(const std::string& text);
bool isAxis(Role role);
/// \brief Whether payloads to this role make the machine move or cut (everything but generic).
bool startsMotion(Role role);

struct SlaveConfig
{
  uint8_t address = 0;  ///< 1..kMaxSlaves, its place in every step frame
  std::string name;     ///< topic name part: letters, digits, '_', starting with a letter
  Role role = Role::kGeneric;
  Encoding encoding = Encoding::kBytes;
  double scale = 1.0;  ///< device units per metre (axes)
};

/// \brief The configured slaves of one bus. Immutable after construction, so thread-safe.
class SlaveTable
{
 public:
  /// \param bus_size slaves in every frame; 0: the highest configured address.
  /// \param slaves_name, bus_size_name name the settings in errors ("/cell/bus/slave_bus_node/slaves").
  /// \throws ConfigError naming the entry (slaves_name[i]) or setting and what is wrong with it.
  SlaveTable(std::vector<SlaveConfig> slaves, size_t bus_size, WireFormat wire, const std::string& slaves_name,
             const std::string& bus_size_name);

  const std::vector<SlaveConfig>& slaves() const { return slaves_; }
  size_t busSize() const { return bus_size_; }
  size_t axisCount() const { return axis_count_; }
  const WireFormat& wire() const { return wire_; }
  /// \returns the index into slaves() of the slave at \p address, or -1 for an unconfigured address.
  int indexOf(uint8_t address) const;

  /// \brief Whether a payload to \p address moves or cuts: an axis or tool slave, or an address
  /// nobody configured (what it drives is unknown, so it counts as motion).
  bool startsMotion(uint8_t address) const;

  /// \brief A command's payload for slave \p index: raw \p data, or \p values (an axis: one position
  /// in m, scaled to device units; others: integers), encoded as the slave's encoding.
  /// \throws ProtocolError saying what is wrong (both or neither given, range, length).
  std::vector<uint8_t> commandPayload(size_t index, const std::vector<double>& values,
                                      const std::vector<uint8_t>& data) const;

  /// \brief An explicit step frame, (address, payload) pairs, as the step's payloads.
  /// \throws ProtocolError for an address outside the bus, two payloads for one address, or a
  /// payload too long for the master.
  StepPayloads framePayloads(const std::vector<std::pair<uint8_t, std::vector<uint8_t>>>& payloads) const;

  /// \brief The values of a reply of slave \p index (an axis: m). \throws ProtocolError if the
  /// payload does not decode in the slave's encoding.
  std::vector<double> replyValues(size_t index, const std::vector<uint8_t>& payload) const;

  /// \brief Why a payload is too long, in words an operator can act on.
  std::string payloadLimit() const;

 private:
  std::vector<SlaveConfig> slaves_;
  std::map<uint8_t, size_t> by_address_;
  size_t bus_size_ = 0;
  size_t axis_count_ = 0;
  WireFormat wire_;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
