// The qCNC settings file (docs/protocols/ethernut.md#settings-file), read so that people moving
// from qCNC can keep theirs:
// '#' starts a comment, 'TSS' must appear somewhere to mark the file valid (a word of its own on
// a line without '|', or a setting named TSS; not in a comment), and each setting is `NAME|value`. Only the settings
// this bridge uses are interpreted; the others are kept as text.
#pragma once

#include <cstdint>
#include <istream>
#include <map>
#include <optional>
#include <string>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief What a qCNC settings file said. Unset optionals: the file did not name the setting.
struct Settings
{
  std::optional<std::string> address;         ///< INET_ADD: the board's IP address or host name
  std::optional<uint16_t> port;               ///< INET_PORT (qCNC default 6666)
  std::optional<uint32_t> dead_link_ms;       ///< INET_DEL: ms of silence before the link is dead
  std::optional<bool> kill_enabled;           ///< PROG_CNCkill 0/1
  std::optional<std::string> serial_device;   ///< SERIAL_DEV (qCNC's debug port; not used here)
  std::map<std::string, std::string> values;  ///< every NAME|value pair as written (trimmed)
};

/// \brief Parses a settings file.
/// \param source for messages (the file name).
/// \throws ConfigError naming the source and line: no TSS marker, a line without '|', an empty
///         name, a bad number or flag, a '|' or '#' inside a value (not allowed by qCNC).
Settings parseSettings(std::istream& in, const std::string& source);

/// \brief Reads and parses \p path. \throws ConfigError also if the file cannot be opened.
Settings readSettingsFile(const std::string& path);
}  // namespace ethernut
}  // namespace cnc_bridge
