// Sharing one serial line between nodes. A Haas Classic control can freeze if it is polled for
// status (Q commands) while a DNC transfer runs on the same port, so the node doing the transfer
// holds this lock for its duration and pollers skip their polls while it is held. The lock is an
// advisory flock(2) on a file named after the device, so it works across processes and is
// released by the kernel if the holder dies.
#pragma once

#include <string>

namespace cnc_bridge
{
/// \brief An exclusive, inter-process lock on one serial device. Not thread-safe.
class PortLock
{
 public:
  /// \param device the serial device (symbolic links are resolved so both nodes agree).
  /// \param lock_dir where lock files live (default /tmp).
  explicit PortLock(const std::string& device, const std::string& lock_dir = "/tmp");
  ~PortLock();
  PortLock(const PortLock&) = delete;
  PortLock& operator=(const PortLock&) = delete;

  /// \returns true if the lock was taken (or is already held by this object).
  bool tryLock();
  void unlock();
  bool held() const { return held_; }

  /// \returns true if some other holder has the lock right now (probes without keeping it).
  bool heldElsewhere();

  const std::string& lockFile() const { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
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
