// Moving programs between a program folder and a store (a machine's share), one transfer at a
// time, each program kept in the archive, with the counts share_node shows in its diagnostics
// (docs/share_node.md). The slot, the counters and the file rules are the transfer core's, shared
// with dnc_node (transfer_core.h). ROS-free: the node maps goals and services onto run().
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_store.h"
#include "cnc_bridge/programs/transfer_core.h"

namespace cnc_bridge::programs
{
/// \brief What the transfers and the store's checks came to so far.
using TransferCounts = TransferTotals;

/// \brief What one transfer did.
struct TransferOutcome
{
  bool success = false;
  bool refused = false;    ///< not attempted: busy, a protected program, a bad name
  bool link_lost = false;  ///< failed because the store no longer answers (LinkError)
  uint64_t bytes = 0;
  std::string message;  ///< "sent O01234.nc to <store>/O01234.nc (300 bytes)", or why not
};

/// \brief Sends programs from a program folder into a store and receives them back. Thread-safe;
/// one transfer at a time (another is refused while one runs).
class ProgramTransfers
{
 public:
  enum class Direction
  {
    kSend,    ///< program folder -> store
    kReceive  ///< store -> program folder (atomic, getProgram())
  };

  /// \param source the node and machine versions are kept under (direction set per transfer).
  ProgramTransfers(ProgramStore& store, const ProgramDirectory& folder, ProtectedRange range, NamePattern pattern,
                   ProgramArchive& archive, VersionSource source);

  /// \brief Moves \p file (relative to the program folder; its base name on the store). \p started
  /// is called once the transfer has the store (not when refused as busy). Does not throw.
  TransferOutcome run(Direction direction, const std::string& file, const StoreProgress& progress = nullptr,
                      const std::function<void()>& started = nullptr);
  /// \brief Stops a running transfer between two chunks (it fails as cancelled).
  void cancel() { slot_.cancelFlag() = true; }
  /// \brief Whether the running (or last) transfer was asked to stop.
  bool cancelled() const { return slot_.cancelFlag(); }
  bool busy() const { return slot_.busy(); }
  /// \brief Counts one check of the store (a listing) and its round trip; \p error "" if it answered.
  /// \returns whether the error differs from the last one (worth a log line).
  bool countCheck(double round_trip, const std::string& error) { return counters_.countCheck(round_trip, error); }
  TransferCounts counts() const { return counters_.totals(); }

 private:
  TransferOutcome transfer(Direction direction, const std::string& file, const StoreProgress& progress);
  void keep(const std::string& name, const std::string& path, const std::string& direction);

  ProgramStore& store_;
  const ProtectedRange range_;
  const NamePattern pattern_;
  const VersionSource source_;
  const TransferFiles files_;  ///< over the folder, range_, pattern_ and the archive
  TransferSlot slot_;
  TransferCounters counters_;
};
}  // namespace cnc_bridge::programs
