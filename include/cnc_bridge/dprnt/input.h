// Where DPRNT bytes come from. A Haas Classic prints to its RS-232 port, which is always open;
// an NGC can also print to a TCP port (setting 261 = TCP, port in setting 263; the control listens,
// we connect) or append to a file (setting 262), usually on a network share. All three are one
// interface so the node and its tests do not care which: bytes in, link state out, and the input
// keeps itself connected (reopen a vanished USB adapter, reconnect a dropped socket with backoff,
// follow a file through rotation and truncation).
#pragma once

#include <sys/types.h>

#include <atomic>
#include <ctime>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/reconnecting_link.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace dprnt
{
/// \brief A source of DPRNT bytes that runs in its own thread.
class DprntInput
{
 public:
  /// Called from the input thread with every chunk read.
  using BytesHandler = std::function<void(const uint8_t* data, size_t size)>;
  /// Called from the input thread on every link change; \p why is empty when there is nothing to say.
  using StateHandler = std::function<void(LinkState state, const std::string& why)>;
  /// Called from the input thread when the byte stream starts over while the link stays up (a
  /// followed file was truncated, rewritten or rotated), before any byte of the new content: an
  /// unfinished line held by the reader belongs to the old content and must not be glued to it.
  using RestartHandler = std::function<void(const std::string& why)>;

  virtual ~DprntInput() = default;
  /// \brief Starts the input thread. Handlers must stay valid until stop() returns; \p on_restart
  /// may be empty.
  virtual void start(BytesHandler on_bytes, StateHandler on_state, RestartHandler on_restart = nullptr) = 0;
  /// \brief Stops and joins the input thread; no handler runs after it returns. Thread-safe.
  virtual void stop() = 0;
  /// \brief "/dev/ttyUSB0@9600 8N1", "10.0.0.5:5051", "file /mnt/haas/dprnt.txt".
  virtual std::string describe() const = 0;
  /// \brief Times the link came back after a failure (reconnects, reopened files).
  virtual unsigned reconnects() const = 0;
};

/// \brief Any Transport that can be reopened: a serial port or a TCP client. Thread-safe.
///
/// A ReconnectingLink opens the link with \p open, reads until it fails, and reopens it after a
/// capped exponential backoff, so a machine switched off overnight is picked up in the morning.
class StreamInput : public DprntInput
{
 public:
  /// \param open creates and opens the link; throws LinkError/ConfigError when it cannot.
  /// \param description for messages and diagnostics.
  StreamInput(std::function<std::unique_ptr<Transport>()> open, std::string description, Backoff backoff = Backoff());
  ~StreamInput() override;

  /// A stream never restarts while up (a reconnect is a link change): \p on_restart is not called.
  void start(BytesHandler on_bytes, StateHandler on_state, RestartHandler on_restart = nullptr) override;
  void stop() override;
  std::string describe() const override { return description_; }
  unsigned reconnects() const override;

 private:
  void session(Transport& link);

  std::function<std::unique_ptr<Transport>()> open_;
  std::string description_;
  Backoff backoff_;
  BytesHandler on_bytes_;
  std::atomic<bool> stopping_{false};
  std::unique_ptr<ReconnectingLink> link_;
};

/// \brief Follows a file the control appends DPRNT output to (Haas NGC setting 262). Thread-safe.
///
/// Polls rather than using inotify: the file normally lives on an SMB share the control writes to
/// from another host, and inotify never sees remote writes. Each poll reads what was appended.
///
/// Start-overs (each told to the restart handler, then to the state handler: link UP, with a message):
///   - truncated: the file is shorter than what was read; reading restarts at its beginning;
///   - rewritten: truncated and written past the old length between two polls. The size alone
///     cannot tell, so when size or modification time changed, the last bytes read (up to
///     kVerifyWindow) are read again from the file; if they differ, the file was rewritten and is
///     read from its beginning. A rewrite whose bytes up to the old length equal the old ones
///     is indistinguishable from an append (nothing but inotify could tell; see docs/dprnt_node.md);
///   - rotated: the inode changed (renamed away, a new file created): the rest of the old file is
///     read, then the new one from its beginning.
/// A missing file is waited for (link CONNECTING/DOWN) with backoff.
class FileInput : public DprntInput
{
 public:
  /// \param from_start read what the file already holds when start() finds it (else start at its
  ///        end); a file that appears later is always read from its start.
  /// \param poll how often to look for new data.
  FileInput(std::string path, bool from_start, Milliseconds poll = Milliseconds(50), Backoff backoff = Backoff());
  ~FileInput() override;

  /// Bytes before the read position compared to detect a rewrite (see the class comment).
  static constexpr size_t kVerifyWindow = 4096;

  void start(BytesHandler on_bytes, StateHandler on_state, RestartHandler on_restart = nullptr) override;
  void stop() override;
  std::string describe() const override { return "file " + path_; }
  unsigned reconnects() const override;
  /// \brief Truncations, rewrites and rotations seen so far.
  unsigned restarts() const { return restarts_; }

 private:
  void openFile();
  void session();
  void closeFile();
  /// Before reading after a poll: was the file truncated or rewritten under the read position?
  /// Returns the reason ("truncated", "rewritten") or nullptr.
  const char* changedUnderneath();
  void keepTail(const uint8_t* data, size_t size);
  void startOver(const std::string& why);

  std::string path_;
  bool from_start_;
  Milliseconds poll_;
  Backoff backoff_;
  BytesHandler on_bytes_;
  StateHandler on_state_;
  RestartHandler on_restart_;
  int fd_ = -1;
  std::string tail_;      // the last bytes read (up to kVerifyWindow), to detect a rewrite
  off_t seen_size_ = -1;  // size and modification time at the last check: unchanged means no rewrite
  struct timespec seen_mtime_ = {0, 0};
  bool first_attempt_ = true;
  StopSignal stop_;
  std::atomic<unsigned> restarts_{0};
  std::unique_ptr<Reconnector> reconnector_;
};
}  // namespace dprnt
}  // namespace cnc_bridge
