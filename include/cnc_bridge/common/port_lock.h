// Sharing one serial line between nodes. A Haas Classic control can freeze if it is polled for
// status (Q commands) while a DNC transfer runs on the same port, and a query in flight when a
// transfer starts would write `?Qnnn` into the transfer and read its first bytes as a reply. So
// every use of the line holds this lock: a status poller for each query (tryLockForQuery), a
// transfer for its whole length (lockForTransfer). A transfer waiting for a query to finish goes
// first: pollers skip their queries while it waits. The lock is an advisory flock(2) on a file
// named after the device, so it works across processes and is released by the kernel if the
// holder dies.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

namespace cnc_bridge
{
/// The default directory of port locks, out of the world-writable /tmp: created by the first node
/// that needs it, mode 0755 (only its user writes there), so every node of that user on the line
/// finds the same locks and nobody else can plant a file or a link among them.
constexpr const char* kDefaultLockDir = "/run/lock/cnc_bridge";

/// \brief The directory to keep port locks in when \p requested is asked for. A directory other than
/// kDefaultLockDir is used as given (it must exist). The default is created if missing (its parent
/// /run/lock must exist) and used only if it is a real directory (not a link) owned by this user or
/// root that no other user can write to; otherwise, or if it cannot be created, the locks go to
/// `/tmp/cnc_bridge-<uid>` (mode 0700, checked the same way) and a warning says so (every node on
/// the line falls back alike, as one user). \throws ConfigError if neither can be used.
std::string lockDirectory(const std::string& requested);

/// \brief The name of the lock of serial port \p device: a device path with its symbolic links
/// resolved (so /dev/serial/by-id/... and /dev/ttyUSB0 share one lock), or for a device server's port
/// (tcp://host:port, rfc2217://host:port) "net-host:port" (nodes reaching one server port by either
/// protocol share one lock), '/' made '_'.
std::string lockName(const std::string& device);

/// \brief An exclusive, inter-process lock on one serial device. Not thread-safe.
///
/// Files: `<lock_dir>/cnc_bridge-<device>.lock` (the lock; holds the transfer generation as text)
/// and `<...>.lock.want` (held by a transfer waiting for the lock). They are created mode 0640 and
/// opened without following symbolic links and without truncating: a link, a FIFO or anything but a
/// regular file at their path is refused with an error, never written through.
class PortLock
{
 public:
  /// \param device the serial device or device server URL (lockName()).
  /// \param lock_dir where lock files live (lockDirectory(): the default is created); every node on
  /// the line must use the same. \throws ConfigError if the default cannot be set up.
  explicit PortLock(const std::string& device, const std::string& lock_dir = kDefaultLockDir);
  ~PortLock();
  PortLock(const PortLock&) = delete;
  PortLock& operator=(const PortLock&) = delete;

  /// \returns true if the lock was taken (or is already held by this object).
  /// \throws LinkError if the lock file cannot be opened or is not a regular file (a planted link).
  bool tryLock();
  void unlock();
  bool held() const { return held_; }

  /// \brief Takes the lock for one short use of the line (a status query), only if it is free and
  /// no transfer is waiting for it (lockForTransfer()).
  bool tryLockForQuery();

  /// \brief Takes the lock for a transfer: tries again every 20 ms for up to \p patience while it
  /// is held elsewhere (a query in flight), meanwhile telling pollers to leave it alone. On success
  /// the generation is bumped, so pollers know another protocol has used the line.
  /// \param cancelled polled while waiting; true gives up.
  /// \returns false if the lock stayed held elsewhere or the wait was cancelled.
  bool lockForTransfer(std::chrono::milliseconds patience, const std::function<bool()>& cancelled = {});

  /// \brief How many transfers have held the lock (stored in the lock file). Read it while holding
  /// the lock. 0 when never used.
  uint64_t generation();

  /// \returns true if some other holder has the lock right now (probes without keeping it).
  bool heldElsewhere();
  /// \returns true if a transfer is waiting for the lock.
  bool wantedElsewhere();

  const std::string& lockFile() const { return path_; }

 private:
  void open();

  std::string path_;
  int fd_ = -1;
  int want_fd_ = -1;
  bool held_ = false;
};

/// \brief Holds a PortLock for a scope; throws LinkError if it is held elsewhere.
class ScopedPortLock
{
 public:
  explicit ScopedPortLock(PortLock& lock);
  ~ScopedPortLock() { lock_.unlock(); }

 private:
  PortLock& lock_;
};
}  // namespace cnc_bridge
