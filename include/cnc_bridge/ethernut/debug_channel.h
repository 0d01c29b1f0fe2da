// The board's serial debug channel (qCNC section 4, "Serial debug"; SERIAL_DEV of its settings
// file): the board prints messages on its RS-232 port, and qCNC only received them and listed
// them. DebugLineSplitter turns those bytes into lines, bounded and printable; DebugChannel reads
// them from a serial link opened through the link factory (a device path, tcp:// or rfc2217:// at a
// device server), keeps the link open with backoff and counts what it saw. ROS-free.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief One line of the board's debug output.
struct DebugLine
{
  std::string text;           ///< printable ASCII and TAB; other bytes as \xNN, a backslash as \\ .
  bool cut = false;           ///< longer than the limit: text is its beginning, the rest was dropped
  bool unterminated = false;  ///< the link went away before the line's end: what had arrived

  /// \brief The text as published: with " [cut]" or " [unterminated]" when so.
  std::string display() const;
};

/// \brief What the splitter saw. Plain data.
struct DebugLineStats
{
  uint64_t bytes = 0;          ///< every byte fed
  uint64_t lines = 0;          ///< lines delivered (cut and unterminated ones included)
  uint64_t cut_lines = 0;      ///< lines longer than the limit, cut
  uint64_t dropped_bytes = 0;  ///< bytes of cut lines beyond the limit, dropped
  uint64_t escaped_bytes = 0;  ///< bytes that are not text, delivered as \xNN
  uint64_t empty_lines = 0;    ///< line ends with no text (the second end of LF CR), not delivered
  uint64_t unterminated = 0;   ///< unfinished lines delivered when the link went away
};

/// \brief Splits the debug byte stream into lines. Not thread-safe (one reader feeds it).
///
///   - CR and LF end a line; an LF right after a CR belongs to the same end (CR LF); empty lines
///     are counted, not delivered;
///   - bytes 0x20..0x7E and TAB are text; a backslash becomes \\ and every other byte \xNN (two
///     hex digits), counted as escaped, so garbage or a wrong baud rate shows instead of vanishing;
///   - a line is at most max_length characters (escapes included): a longer one is delivered cut
///     once, and what follows up to the next line end is dropped and counted. Memory never grows
///     past max_length, whatever arrives.
class DebugLineSplitter
{
 public:
  using Handler = std::function<void(const DebugLine&)>;

  /// \param max_length longest line delivered, in characters (at least 8: room for one escape).
  explicit DebugLineSplitter(size_t max_length = 256);

  /// \brief Feeds bytes; calls \p handler for every line they finish (or cut).
  void feed(const uint8_t* data, size_t size, const Handler& handler);
  /// \brief The link went away: delivers the unfinished line, if any, as unterminated, and starts over.
  void endOfStream(const Handler& handler);

  const DebugLineStats& stats() const { return stats_; }
  size_t maxLength() const { return max_length_; }
  /// \brief Characters of the unfinished line held (never more than maxLength()).
  size_t pending() const { return line_.size(); }

 private:
  void append(uint8_t byte, const Handler& handler);
  void endLine(const Handler& handler);

  size_t max_length_;
  std::string line_;
  bool skipping_ = false;  // inside a cut line, until its end
  bool after_cr_ = false;  // the previous byte was CR: an LF now is the second half of CR LF
  DebugLineStats stats_;
};

/// \brief Where the debug channel is read and how.
struct DebugChannelSettings
{
  /// A serial line: serial.device is a path, tcp://host:port or rfc2217://host:port. Input the port
  /// held before it was opened is kept: it is what the board said meanwhile.
  LinkSettings link;
  size_t max_line = 256;  ///< characters; a longer line is cut (DebugLineSplitter)
  /// Reopening after a failure or a vanished port: 0.2 s .. 5 s, as the board's TCP link.
  Backoff backoff{Milliseconds(200), Milliseconds(5000)};
};

/// \brief What diagnostics show of the channel. Plain data.
struct DebugChannelStatus
{
  LinkState link = LinkState::kDown;
  std::string why;     ///< the last failure, empty while up
  std::string device;  ///< LinkSettings::hardwareId()
  DebugLineStats counts;
  std::string last_line;  ///< display() of the last line delivered; empty before the first
  unsigned reconnects = 0;
};

/// \brief Reads the board's debug lines in its own thread, reopening the link when it fails or the
/// port vanishes (a USB adapter unplugged, a device server restarted). Thread-safe.
class DebugChannel
{
 public:
  using LineHandler = std::function<void(const DebugLine&)>;
  using StateHandler = ReconnectingLink::StateHandler;

  /// \throws ConfigError for invalid settings (checked here, once).
  explicit DebugChannel(DebugChannelSettings settings);
  ~DebugChannel();
  DebugChannel(const DebugChannel&) = delete;
  DebugChannel& operator=(const DebugChannel&) = delete;

  /// \brief Starts reading. Handlers run on the channel's thread and must stay valid until stop();
  /// \p on_state may be empty.
  void start(LineHandler on_line, StateHandler on_state = nullptr);
  /// \brief Stops and joins the thread; no handler runs after it returns. Idempotent.
  void stop();

  DebugChannelStatus status() const;

 private:
  void session(Transport& link);
  void deliver(const std::vector<DebugLine>& lines);

  DebugChannelSettings settings_;
  LinkFactory open_;
  LineHandler on_line_;
  StateHandler on_state_;
  std::atomic<bool> stopping_{false};
  mutable std::mutex mutex_;  // guards splitter_ and status_
  DebugLineSplitter splitter_;
  DebugChannelStatus status_;
  std::unique_ptr<ReconnectingLink> link_;
};
}  // namespace ethernut
}  // namespace cnc_bridge
