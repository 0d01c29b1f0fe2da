// Commissioning a serial link in words: why a port cannot be opened (missing device, permission,
// busy) and what the bytes a control sends say about its line settings. Used by SerialPort's
// open errors (so every node and cnc_dnc carry the explanation) and by `cnc_dnc doctor`.
#pragma once

#include <sys/types.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge
{
/// The hint for a control that does not answer: what to compare and how to look at the line.
extern const char* const kNoAnswerHint;

/// \brief Why \p device could not be opened, with the fix, from the errno of the failed open:
/// a missing device lists the serial adapters present (\p by_id_dir, /dev/serial/by-id); a
/// permission error names the device's owner, group and mode, the user and the group to join
/// (`usermod -aG GROUP USER`, then log in again); a busy device names the processes holding it.
std::string explainOpenFailure(const std::string& device, int error_number,
                               const std::string& by_id_dir = "/dev/serial/by-id");

/// \brief Why a TCP connection to \p host (":port" in \p where) failed, with what to check: nothing
/// listening (the control's server off or another port), no route, no answer in time
/// (\p error_number 0 for a timeout).
std::string explainConnectFailure(const std::string& where, int error_number);

/// \brief The processes that hold \p device open (its path or any link to it), as
/// "PID (command)", from /proc/<pid>/fd; \p except is left out (-1: none).
std::vector<std::string> processesHolding(const std::string& device, pid_t except = -1);

/// \brief processesHolding() less the far end of a pty: a process that holds the pty's master
/// (a simulated control, socat) is the peer on the line, not a program competing for the port.
std::vector<std::string> processesCompetingFor(const std::string& device, pid_t except = -1);

/// \brief What the holder "PID (command)" of a port is, in words: a node, tool or simulator of this
/// suite (and how to stop it), or another program.
std::string describeHolder(const std::string& holder);

/// \brief The serial adapters in \p by_id_dir as "name -> /dev/ttyUSB0".
std::vector<std::string> serialAdaptersById(const std::string& by_id_dir = "/dev/serial/by-id");

/// \brief What the bytes a control sent, read as 8 data bits without parity, say about the
/// control's line settings. With 7 data bits and a parity bit, bit 7 of every byte read this way
/// is the control's parity bit; a baud rate that differs garbles the characters and (on a real
/// UART) gives framing errors.
struct LineGuess
{
  size_t bytes = 0;           ///< received, NUL leader/trailer left out
  size_t framing_errors = 0;  ///< reported by the driver (a pty reports none)
  double text_share = 0;      ///< of the bytes, the share whose low 7 bits are NC-program text
  unsigned data_bits = 0;     ///< 7 or 8; 0 when nothing or nothing clear was received
  char parity = '?';          ///< 'N', 'E', 'O', 'M' (bit 7 always set), '?' unknown
  bool baud_suspect = false;  ///< the characters are not text, or framing errors: the baud rate likely differs
  /// What a peer that speaks a protocol is doing, when its bytes say so (an XModem receiver
  /// repeating NAK or 'C', a control asking for a drip-feed with DC1), else empty; such bytes
  /// arriving intact mean the line is good, though they are not program text.
  std::string peer;
  std::string line;                   ///< what the settings look like, in words
  std::vector<std::string> profiles;  ///< config/controls/ profiles with these data bits and parity
};

/// \brief Judges \p bytes (as read at 8N1 at \p baud) and the driver's framing error count.
LineGuess guessLineSettings(const std::vector<uint8_t>& bytes, size_t framing_errors, unsigned baud);

/// \brief A control profile's line settings (config/controls/<name>.yaml).
struct ProfileLine
{
  const char* name;
  unsigned baud;
  unsigned data_bits;
  char parity;
  unsigned stop_bits;
};
/// \brief The serial profiles of config/controls/ (test_port_doctor checks them against the files).
const std::vector<ProfileLine>& serialProfiles();
}  // namespace cnc_bridge
