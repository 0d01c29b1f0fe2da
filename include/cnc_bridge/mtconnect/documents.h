// MTConnect response documents as plain structs: MTConnectDevices (/probe), MTConnectStreams
// (/current, /sample) and MTConnectError. Parsed with tinyxml2; element names are taken without
// their namespace prefix, so agents of MTConnect 1.1 to 2.x and their extensions read the same.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace cnc_bridge::mtconnect
{
/// \brief The Header of every MTConnect document (the sequence fields of a Streams document).
struct Header
{
  std::string instance_id;  ///< changes when the agent restarts (its buffer starts afresh)
  std::string version;
  std::string creation_time;
  std::string sender;
  uint64_t buffer_size = 0;
  uint64_t first_sequence = 0;  ///< oldest observation still in the agent's buffer
  uint64_t last_sequence = 0;   ///< newest observation
  uint64_t next_sequence = 0;   ///< what to ask from next
};

/// \brief One DataItem of a probe, with where it sits.
struct DataItem
{
  std::string id;
  std::string name;
  std::string type;      ///< POSITION, EXECUTION, ...
  std::string sub_type;  ///< ACTUAL, COMMANDED, ...
  std::string category;  ///< SAMPLE, EVENT, CONDITION
  std::string units;     ///< what the agent reports in (MILLIMETER, REVOLUTION/MINUTE, ...)
  std::string native_units;
  std::string component_type;  ///< element name of the owning component: Linear, Path, Controller, Device
  std::string component_name;  ///< X, path, controller, the device's name
  std::string component_id;
  std::string device;  ///< name of the device it belongs to
};

struct Device
{
  std::string id;
  std::string name;
  std::string uuid;
  bool is_agent = false;  ///< the <Agent> pseudo-device of MTConnect 1.7+
  std::vector<DataItem> data_items;
};

/// \brief One observation of a Streams document.
struct Observation
{
  std::string device;    ///< DeviceStream name
  std::string element;   ///< Position, Execution, ...; for a condition: Normal, Warning, Fault, Unavailable
  std::string category;  ///< SAMPLE, EVENT or CONDITION (from the Samples/Events/Condition group)
  std::string data_item_id;
  std::string name;
  std::string sub_type;
  std::string condition_type;  ///< a condition's type attribute (SYSTEM, MOTION_PROGRAM, ...)
  uint64_t sequence = 0;
  std::string timestamp;
  std::string value;            ///< text content; UNAVAILABLE when the agent knows no value
  std::string native_code;      ///< conditions
  std::string native_severity;  ///< conditions
  std::string qualifier;        ///< conditions: HIGH, LOW
  bool unavailable() const { return value == "UNAVAILABLE" || element == "Unavailable"; }
};

struct AgentError
{
  std::string code;  ///< OUT_OF_RANGE, NO_DEVICE, INVALID_XPATH, ...
  std::string text;
};

enum class DocumentKind
{
  kDevices,
  kStreams,
  kError
};

struct Document
{
  DocumentKind kind = DocumentKind::kStreams;
  Header header;
  std::vector<Device> devices;            ///< kDevices
  std::vector<Observation> observations;  ///< kStreams, in document order
  std::vector<AgentError> errors;         ///< kError
  /// \returns the error codes and texts in one line, for messages.
  std::string errorText() const;
  bool hasError(const std::string& code) const;
};

/// \brief Parses one MTConnect document.
/// \throws ProtocolError naming what is wrong (not XML, not MTConnect, a header without its
///         sequence numbers, larger than \p max_bytes) and how the document begins.
Document parseDocument(std::string_view xml, size_t max_bytes = 16u << 20u);

/// \brief The device to follow: the one named \p name (name or uuid), or the first that is not
/// the agent's own when \p name is empty. \throws ConfigError listing the devices there are.
const Device& selectDevice(const Document& probe, const std::string& name);
}  // namespace cnc_bridge::mtconnect
