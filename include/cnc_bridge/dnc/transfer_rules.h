// What dnc_node decides about a transfer without ROS (docs/dnc_node.md): which file a request may
// touch (inside the program directory; protected program numbers refused on send), what a refusal
// says while another transfer runs, the program kept in the archive after a transfer, the counters
// behind the node's "Transfers" diagnostics, and the XModem waits set from the node's parameters.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/session.h"

namespace cnc_bridge::dnc
{
/// \brief A transfer request checked before the port is touched.
struct JobCheck
{
  std::string path;     ///< the file inside the program directory; empty when refused
  std::string refusal;  ///< why not, "refused: ..." or the reason the file cannot be sent
  /// A refusal counted as such (a protected program, an unreadable file); a name outside the
  /// program directory is answered but not counted.
  bool counted = false;
  bool accepted() const { return refusal.empty(); }
};

/// \brief The files transfers may use: a program directory, the protected range and the archive
/// every program sent or received is kept in. Holds references; thread-compatible as its parts.
class TransferFiles
{
 public:
  TransferFiles(const ProgramDirectory& programs, const programs::ProtectedRange& protected_range,
                const programs::NamePattern& names, programs::ProgramArchive& archive)
      : programs_(programs), protected_(protected_range), names_(names), archive_(archive)
  {
  }

  /// \brief Resolves \p file for sending (it must exist and not be protected) or receiving.
  JobCheck check(const std::string& file, bool send) const;

  /// \brief The protected-range check of the contents actually sent as \p file (the name a request
  /// gave): run by xmodem::sendFile() on the bytes it read, so a file swapped since check() is caught.
  xmodem::ContentCheck sendCheck(const std::string& file) const;

  /// \brief Keeps the program at \p path in the archive, from \p source (node, machine, "sent"...).
  /// \returns "kept O01234.nc as version 3 in <archive>", or "" when that content was kept already.
  /// \throws Error if the file or the archive cannot be read or written.
  std::string archive(const std::string& path, const programs::VersionSource& source) const;

 private:
  const ProgramDirectory& programs_;
  const programs::ProtectedRange& protected_;
  const programs::NamePattern& names_;
  programs::ProgramArchive& archive_;
};

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

/// \brief Transfer counts since the node started.
struct TransferTotals
{
  uint64_t transfers = 0, completed = 0, failed = 0, cancelled = 0, refused = 0;
  uint64_t blocks = 0, retries = 0, timeouts = 0, bytes = 0;
  uint64_t requests = 0, requests_served = 0;  ///< program requests punched by the control
  std::string last_result;

  /// \brief The last transfer failed (a result that says so after at least one failure).
  bool lastFailed() const { return failed > 0 && last_result.find("fail") != std::string::npos; }
  /// \brief The counts by the names diagnostics show, requests only when \p with_requests.
  std::vector<std::pair<std::string, uint64_t>> fields(bool with_requests) const;
};

class TransferCounters;

/// \brief Sends the file at \p path by XModem, or receives it there; \p protocol is xmodem,
/// xmodem-crc or xmodem-1k. The timeouts, and the retries of a failed transfer (a successful one
/// reports its own), are added to \p counters.
/// \param check run on the contents of a file to send before its first byte goes (TransferFiles::sendCheck()).
/// \throws the errors of xmodem::sendFile() and xmodem::receiveFile().
xmodem::FileResult transferByXmodem(Transport& link, const std::string& path, bool send, const std::string& protocol,
                                    const xmodem::Config& config, const xmodem::TextOptions& text,
                                    const xmodem::ProgressCallback& progress, const std::atomic<bool>& cancel,
                                    TransferCounters& counters, const xmodem::ContentCheck& check = nullptr);

/// \brief Counts transfers and their outcomes. Thread-safe.
class TransferCounters
{
 public:
  void refused();
  void started();
  /// \brief A transfer ended: completed, cancelled or failed, with its blocks, retries and bytes.
  void finished(bool success, bool cancelled, uint64_t blocks, uint64_t retries, uint64_t bytes,
                const std::string& message);
  /// \brief XModem's timeouts, and retries of a failed transfer (a successful one reports its own).
  void xmodemStats(uint64_t timeouts, uint64_t failed_retries);
  void request(bool served);
  TransferTotals totals() const;

 private:
  mutable std::mutex mutex_;
  TransferTotals totals_;
};
}  // namespace cnc_bridge::dnc
