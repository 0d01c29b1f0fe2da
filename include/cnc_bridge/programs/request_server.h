// Serving program requests that reach a share_node (docs/share_node.md, "Program requests from
// the control"): request files the control drops in the share's requests folder, and DPRNT lines
// `LOAD O1234`. Each is recognised (recogniseRequest), decided as on every wire (decideRequest),
// carried out by the caller's transfer (send into the share, or fetch from it), and reported.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::programs
{
/// \brief What became of one request (share_node publishes it on program_requests).
struct RequestOutcome
{
  std::string source;   ///< "share requests/r1.nc", "dprnt"
  std::string word;     ///< the request's word (LOAD, SEND, SAVE, a shop's own); "" when none was found
  uint32_t number = 0;  ///< the program number asked for
  std::string program;  ///< its file name, by the name pattern
  bool success = false;
  std::string outcome;  ///< the transfer's message, or why nothing was done
};

/// \brief The result of a transfer a request asked for.
struct RequestTransfer
{
  bool success = false;
  std::string message;
};

/// \brief Serves requests by the rules of decideRequest(). serveRequestFiles() is called from one
/// thread at a time; serve() and serveDprntLine() may run beside it (they change no state).
class RequestServer
{
 public:
  /// \brief Sends `program` from the program folder into the share (kSend), or fetches it from the
  /// share into the program folder (kReceive).
  using Transfer = std::function<RequestTransfer(RequestDecision::Action action, const std::string& program)>;
  using Report = std::function<void(const RequestOutcome&)>;
  /// \brief Opens the share's requests folder. \throws Error while it cannot (it does not exist).
  using OpenFolder = std::function<std::unique_ptr<ProgramStore>()>;

  RequestServer(RequestWords words, NamePattern pattern, ProtectedRange range, std::string program_root,
                Transfer transfer, Report report);

  /// \brief Where request files are read from: \p folder (for messages), opened by \p open when
  /// first needed; until then each serveRequestFiles() tries again.
  void setRequestFolder(std::string folder, OpenFolder open);
  /// \brief Reads, removes and serves each file of the requests folder (none when there is no
  /// folder). A folder that cannot be opened or listed is warned about at most once a minute.
  void serveRequestFiles();
  /// \brief Serves \p line when it is a request (`LOAD O1234`); \returns whether it was one.
  bool serveDprntLine(const std::string& line);
  /// \brief Serves what a request file or line held (nothing recognised: reported as such).
  RequestOutcome serve(const std::optional<ProgramRequest>& request, const std::string& source);

 private:
  RequestWords words_;
  NamePattern pattern_;
  ProtectedRange range_;
  std::string program_root_;
  Transfer transfer_;
  Report report_;
  std::string folder_name_;
  OpenFolder open_folder_;
  std::unique_ptr<ProgramStore> folder_;
  std::optional<std::chrono::steady_clock::time_point> last_folder_warning_;
};
}  // namespace cnc_bridge::programs
