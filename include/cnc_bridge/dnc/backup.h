// Program backup: the control punches a program out of its memory (Fanuc PUNCH, Haas SEND RS-232)
// and the host stores it. The control sends no length and no checksum: the program is what lies
// between the first '%' and the second (docs/protocols/drip_feed.md#percent-framing), or, for a control
// set not to send the closing '%', what arrives before the line goes quiet.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace dnc
{
/// \brief Turns the punched byte stream into a program file. Pure: no I/O. Not thread-safe.
///
/// Input as punched: [leader: NULs, DEL, LFs, spaces...] [DC2] '%' EOB block EOB ... '%' [DC4]
/// [trailer], EOB any of LF, CR, CR LF, LF CR CR; under 7E1 read as 8 bits every byte may carry a
/// parity bit. Output: "%\n", the blocks each ending in "\n", "%\n". The parity bit is masked;
/// everything before the first '%' is leader and dropped; NUL, DEL, DC1..DC4 and other control
/// codes (but TAB) are dropped; a run of CR/LF is one end of block (blank lines carry nothing for
/// the control); the second '%' ends the program and anything after it is not consumed.
class BackupParser
{
 public:
  enum class State
  {
    kWaitingForStart,  ///< no '%' yet
    kInProgram,        ///< between the '%'s
    kDone              ///< the closing '%' arrived
  };

  /// \brief Consumes bytes, appending the program text they carry to \p out.
  /// \returns the number of bytes consumed: all of them, or up to and including the closing '%'.
  size_t feed(const uint8_t* data, size_t size, std::string& out);

  /// \brief Ends the program without a closing '%' (quiet timeout): closes the last line.
  void finish(std::string& out);

  State state() const { return state_; }
  /// \brief Lines of program text produced so far ('%' lines included).
  uint64_t lines() const { return lines_; }
  /// \brief Bytes dropped as leader before the first '%'.
  uint64_t leaderBytes() const { return leader_bytes_; }

 private:
  State state_ = State::kWaitingForStart;
  bool at_line_start_ = true;
  uint64_t lines_ = 0;
  uint64_t leader_bytes_ = 0;
};

struct BackupOptions
{
  Milliseconds start_timeout{0};     ///< wait this long for the first '%'; 0 = forever (until cancel)
  Milliseconds quiet_timeout{5000};  ///< after the first '%', this much silence ends the program
  bool send_dc1 = true;              ///< send DC1 when ready: "go on" to a control waiting to punch
  uint64_t max_bytes = 64ull << 30;  ///< refuse a stream longer than this (a babbling line)
  Milliseconds progress_interval{100};
  /// Optional flag another thread sets to cancel (a ROS action preempt); cancel() works as well.
  const std::atomic<bool>* cancel = nullptr;
};

struct BackupProgress
{
  uint64_t bytes = 0;  ///< program bytes stored
  uint64_t line = 0;   ///< line being received (1-based)
  bool started = false;
};

struct BackupResult
{
  uint64_t bytes = 0;             ///< bytes written to the file
  uint64_t lines = 0;             ///< lines in the file
  bool ended_by_percent = false;  ///< false: ended by the quiet timeout
  std::string message;
};

/// \brief Receives one punched program into a file, written atomically. Thread-safe only for
/// cancel().
class BackupReceiver
{
 public:
  using ProgressCallback = std::function<void(const BackupProgress&)>;

  BackupReceiver(Transport& link, BackupOptions options) : link_(link), options_(options) {}

  /// \brief Waits for the program and stores it at \p path (which the caller has confined, e.g.
  /// with ProgramDirectory). The file appears complete or not at all.
  /// \throws TimeoutError if no '%' arrived within start_timeout, CancelledError after cancel(),
  ///         ProtocolError if the stream passes max_bytes, LinkError, ConfigError (path).
  BackupResult receive(const std::string& path, const ProgressCallback& progress = nullptr);

  void cancel() { cancelled_ = true; }

 private:
  Transport& link_;
  BackupOptions options_;
  std::atomic<bool> cancelled_{false};
};
}  // namespace dnc
}  // namespace cnc_bridge
