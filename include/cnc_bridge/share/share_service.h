// What share_node decides for its services, its periodic check of the share and its diagnostics
// (docs/share_node.md), without ROS: which transfers it accepts, when the link state changes,
// when a removal is allowed, how listings, comparisons and a fan-out's result read. The node maps
// ROS messages onto these.
#pragma once

#include <cstdint>
#include <ctime>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/programs/fan_out.h"
#include "cnc_bridge/programs/program_store.h"
#include "cnc_bridge/programs/program_transfers.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge::share
{
/// \brief A transfer asked for by name: its direction, or why it is refused.
struct TransferRequest
{
  std::optional<programs::ProgramTransfers::Direction> direction;  ///< none: refused
  std::string refusal;
};

/// \brief Checks a transfer asked for with \p direction ("send" or "receive", as
/// Transfer.action's DIRECTION_*) over \p protocol ("" or "smb": whole files over SMB).
TransferRequest transferRequest(const std::string& direction, const std::string& protocol);

/// \brief What one periodic check of the share came to.
struct StoreCheck
{
  bool checked = false;    ///< false: skipped, a running transfer says whether the share answers
  std::string error;       ///< "" when the share answered
  bool new_error = false;  ///< an error other than the last one: worth a log line
};

/// \brief Lists \p store to see that it answers, counted with its round trip in \p transfers;
/// skipped while a transfer runs. Throws only what is no cnc_bridge::Error.
StoreCheck checkStore(programs::ProgramStore& store, programs::ProgramTransfers& transfers);

/// \brief A change of the link state shown.
struct LinkChange
{
  LinkState state = LinkState::kDown;
  std::string message;
};

/// \brief The change a check's or a transfer's result (\p error, "" when the share answered)
/// makes to the link state \p shown with \p shown_message; none when it shows that already (the
/// state's message otherwise keeps the last transfer's result).
std::optional<LinkChange> linkChange(LinkState shown, const std::string& shown_message, const std::string& error);

/// \brief A service's answer: whether it did it, and what happened or why not.
struct Answer
{
  bool success = false;
  std::string message;
};

/// \brief ~remove_program: removes \p file from \p store, refused unless \p enabled
/// (~enable_remove). Does not throw: a failure is the answer.
Answer removeProgram(programs::ProgramStore& store, const std::string& file, bool enabled);

/// \brief ~list_programs' number of a listed program: its header's O number, else its file
/// name's, else -1.
int32_t listedNumber(const programs::ProgramListing& listing);

/// \brief ~compare_programs' current version of \p file: the file of its base name in the
/// program folder \p program_root.
std::string currentFile(const std::string& program_root, const std::string& file);

/// \brief ~publish_to_machines' message: "2 of 3 machines got O01234.nc; failed: b (why)", or
/// that no machine was given.
std::string fanOutSummary(const std::vector<programs::TargetResult>& results, const std::string& file);

/// \brief The ~send_program services a ~publish_to_machines target \p machine (resolved) may
/// answer at, in the order tried: a share_node's name, or the namespace a share_node runs in.
std::vector<std::string> sendProgramServices(const std::string& machine);

/// \brief The Share diagnostic's summary.
struct TransfersSummary
{
  bool warn = false;  ///< the last transfer failed
  std::string text;   ///< its error, else the last result, else "no transfer yet"
};
TransfersSummary transfersSummary(const programs::TransferCounts& counts);

/// \brief \p time as the local clock (TZ) reads it, "2026-11-27 18:00 CET", for the log.
std::string localTimeText(std::time_t time);
}  // namespace cnc_bridge::share
