// The transfer core every node that moves programs to a machine shares (dnc_node over a serial
// port, share_node over a share; docs/dnc_node.md, docs/share_node.md): one transfer at a time
// (TransferSlot), one set of counters behind the nodes' "Transfers" diagnostics (TransferCounters),
// and one rule set for the files a transfer may touch, the protected program numbers and the
// archive every program sent or received is kept in (TransferFiles). ROS-free.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge::programs
{
/// \brief One transfer at a time on a machine's link: a transfer reserves the slot or is refused
/// with what holds it; its cancel flag stops the running transfer. Thread-safe.
class TransferSlot
{
 public:
  virtual ~TransferSlot() = default;

  /// \brief Reserves the slot for a transfer, \p what (named in the refusal of another). A cancel
  /// of the previous transfer does not carry over.
  /// \param running set to what holds the slot when it is refused (if given).
  /// \returns false if the slot is reserved already.
  bool tryReserve(const std::string& what, std::string* running = nullptr);
  /// \brief Frees the slot.
  void release();
  bool busy() const;
  /// \brief What holds the slot (the last reservation's \p what).
  std::string running() const;
  /// \brief Set to cancel the running transfer; cleared by each reservation.
  std::atomic<bool>& cancelFlag() { return cancel_; }
  const std::atomic<bool>& cancelFlag() const { return cancel_; }

 protected:
  /// \brief tryReserve() with mutex_ held, for a slot that does more under the same lock.
  bool reserveLocked(const std::string& what, std::string* running);

  mutable std::mutex mutex_;
  std::condition_variable changed_;  ///< notified when the slot is released
  bool busy_ = false;                ///< guarded by mutex_

 private:
  std::string running_;
  std::atomic<bool> cancel_{false};
};

/// \brief Transfer counts since the node started.
struct TransferTotals
{
  uint64_t transfers = 0, completed = 0, failed = 0, cancelled = 0, refused = 0;
  uint64_t blocks = 0, retries = 0, timeouts = 0, bytes = 0;
  uint64_t requests = 0, requests_served = 0;  ///< program requests punched by the control (dnc)
  uint64_t checks = 0, check_failures = 0;     ///< checks of a store that answers without a transfer (share)
  double round_trip = 0;                       ///< s, the last check's
  std::string last_error;                      ///< the last failed transfer's or check's
  std::string last_result;

  /// \brief The last transfer failed (a result that says so after at least one failure).
  bool lastFailed() const { return failed > 0 && last_result.find("fail") != std::string::npos; }
  /// \brief The counts by the names diagnostics show, requests only when \p with_requests.
  std::vector<std::pair<std::string, uint64_t>> fields(bool with_requests) const;
};

/// \brief How a transfer ended.
enum class TransferEnd
{
  kCompleted,
  kFailed,
  kCancelled,
  kRefused  ///< refused once started (a protected program, a bad name)
};

/// \brief Counts transfers and their outcomes. Thread-safe.
class TransferCounters
{
 public:
  /// \brief A transfer refused before it started (busy, a protected program).
  void refused();
  void started();
  /// \brief A transfer ended as \p end, with its blocks, retries and bytes; \p message becomes
  /// the last result (and the last error when it failed).
  void finished(TransferEnd end, uint64_t blocks, uint64_t retries, uint64_t bytes, const std::string& message);
  /// \brief finished(): completed if \p success, else cancelled or failed.
  void finished(bool success, bool cancelled, uint64_t blocks, uint64_t retries, uint64_t bytes,
                const std::string& message);
  /// \brief XModem's timeouts, and retries of a failed transfer (a successful one reports its own).
  void xmodemStats(uint64_t timeouts, uint64_t failed_retries);
  void request(bool served);
  /// \brief Counts one check of the store and its round trip; \p error "" if it answered.
  /// \returns whether the error differs from the last one (worth a log line).
  bool countCheck(double round_trip, const std::string& error);
  TransferTotals totals() const;

 private:
  mutable std::mutex mutex_;
  TransferTotals totals_;
};

/// \brief A transfer request checked before the link is touched.
struct JobCheck
{
  std::string path;     ///< the file inside the program directory; empty when refused
  std::string refusal;  ///< why not, "refused: ..." or the reason the file cannot be sent
  /// A refusal counted as such (a protected program, an unreadable file); a name outside the
  /// program directory is answered but not counted.
  bool counted = false;
  bool accepted() const { return refusal.empty(); }
};

/// \brief The files transfers may use: a program directory, the protected range (with the name
/// pattern that gives a file's number) and the archive every program sent or received is kept in.
/// Holds references; thread-compatible as its parts.
class TransferFiles
{
 public:
  TransferFiles(const ProgramDirectory& programs, const ProtectedRange& protected_range, const NamePattern& names,
                ProgramArchive& archive)
      : programs_(programs), protected_(protected_range), names_(names), archive_(archive)
  {
  }

  /// \brief Resolves \p file for sending (it must exist and not be protected) or receiving.
  JobCheck check(const std::string& file, bool send) const;
  /// \brief Resolves \p file inside the program directory, existing for sending.
  /// \throws ConfigError if it is outside or (sending) does not exist.
  std::string resolve(const std::string& file, bool send) const;

  /// \brief The protected-range check of the contents actually sent as \p file (the name a request
  /// gave), run on the bytes read: a file swapped since check() is caught.
  std::function<void(const std::string& contents)> sendCheck(const std::string& file) const;

  /// \brief Keeps the program at \p path in the archive, from \p source (node, machine, "sent"...).
  /// Only a regular file is read (a link planted since is not followed); its mode is kept.
  /// \returns "kept O01234.nc as version 3 in <archive>", or "" when that content was kept already.
  /// \throws Error if the file or the archive cannot be read or written.
  std::string archive(const std::string& path, const VersionSource& source) const;

  const ProtectedRange& protectedRange() const { return protected_; }
  const NamePattern& names() const { return names_; }

 private:
  const ProgramDirectory& programs_;
  const ProtectedRange& protected_;
  const NamePattern& names_;
  ProgramArchive& archive_;
};
}  // namespace cnc_bridge::programs
