// What dnc_node decides about a transfer without ROS (docs/dnc_node.md): what a refusal says while
// another transfer runs, the XModem waits set from the node's parameters, and an XModem transfer
// counted. The files a request may touch (inside the program directory; protected program numbers
// refused on send), the archive and the counters behind the node's "Transfers" diagnostics are the
// transfer core's, shared with share_node (programs/transfer_core.h).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/transfer_core.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/session.h"

namespace cnc_bridge::dnc
{
// The transfer core dnc_node shares with share_node (programs/transfer_core.h).
using programs::JobCheck;
using programs::TransferCounters;
using programs::TransferFiles;
using programs::TransferTotals;

/// \brief The refusal of a transfer asked for while \p running holds the port \p device. A goal
/// ("goal <id> ...") is named with how to cancel it on \p cancel_topic; a service call runs to its end.
std::string busyRefusal(const std::string& device, const std::string& running, const std::string& cancel_topic);

/// \brief The XModem waits and limits as dnc_node's parameters give them (seconds, 0: from the line).
struct XmodemWaits
{
  Milliseconds start_timeout{120000}, nak_interval{10000}, start_wait{120000};
  Milliseconds block_timeout{10000}, ack_timeout{10000}, eot_quiet{30};
  unsigned wait_characters = 30;
  Milliseconds wait_floor{30};
  Milliseconds char_timeout{0}, purge_quiet{0};  ///< 0: from the line rate (xmodem::fitToLine)
  unsigned max_retries = 10;
};

/// \brief The session configuration for \p waits on a line moving \p characters_per_second.
xmodem::Config xmodemConfig(const XmodemWaits& waits, double characters_per_second);

/// \brief Caps \p config at \p max_bytes of program (XModem has no length field: a peer that sends
/// more is cancelled, nothing stored; a larger file is not sent); errors name \p parameter.
/// \throws ConfigError for fewer than 1 byte.
void setMaxProgramBytes(xmodem::Config& config, long long max_bytes, const std::string& parameter);

/// \brief Progress reports at most every period, and always the last one (the end of the file).
class ProgressThrottle
{
 public:
  explicit ProgressThrottle(double period_s) : period_s_(period_s) {}
  /// \returns true if a report at \p now_s (seconds on any clock) is due; it then counts as made.
  bool due(double now_s, const xmodem::Progress& progress);

 private:
  double period_s_;
  double last_s_ = 0.0;
};

/// \brief Sends the file at \p path by XModem, or receives it there; \p protocol is xmodem,
/// xmodem-crc or xmodem-1k. The timeouts, and the retries of a failed transfer (a successful one
/// reports its own), are added to \p counters.
/// \param check run on the contents of a file to send before its first byte goes (TransferFiles::sendCheck()).
/// \throws the errors of xmodem::sendFile() and xmodem::receiveFile().
xmodem::FileResult transferByXmodem(Transport& link, const std::string& path, bool send, const std::string& protocol,
                                    const xmodem::Config& config, const xmodem::TextOptions& text,
                                    const xmodem::ProgressCallback& progress, const std::atomic<bool>& cancel,
                                    TransferCounters& counters, const xmodem::ContentCheck& check = nullptr);

}  // namespace cnc_bridge::dnc
