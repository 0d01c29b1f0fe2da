// dnc_node's protocols `drip` (send: the control runs the program as it arrives) and `backup`
// (receive: the control punches a program), as transfer session handlers (dnc/transfer_session.h;
// docs/dnc_drip_feed.md): the feed's plan and restart point, the line's flow control for the
// length of a feed, pause and resume of the running feed, and the plan of a feed asked for before
// anything is sent (~plan_drip). ROS-free; the node maps the progress and the lines sent to its
// feedback, state and dnc/current_line.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/dnc/dnc_settings.h"
#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/dnc/transfer_session.h"

namespace cnc_bridge::dnc
{
/// \brief ~pause / ~resume's answer.
struct SwitchAnswer
{
  bool success = false;
  std::string message;
};

/// \brief What a drip-feed of a file would send (~plan_drip), worked out before anything goes.
struct DripPlanAnswer
{
  bool success = false;
  std::string message;
  std::string preamble;
  uint32_t resume_line = 0;
  std::string resume_block;
  std::vector<std::string> warnings;
  std::vector<std::string> character_issues;
  uint64_t character_issue_count = 0;
  uint64_t total_bytes = 0;
};

/// \brief Thread-safe: pause(), resume() and plan() may be called while a feed runs (one feed at
/// a time: the session runs one transfer at a time).
class DripProtocols
{
 public:
  explicit DripProtocols(DripSettings settings) : settings_(std::move(settings)) {}

  /// \brief Called once the feed is planned, before its first byte: what goes out before the file's
  /// first line (the restart preamble) with it.
  using PlannedCallback = std::function<void(const DripPlan&)>;

  /// \brief Feeds job.path to the control (a send). \p progress and \p line_sent as DripSender's.
  /// \throws ConfigError for a receive; the errors of planDrip() (a file the control cannot take).
  TransferOutcome drip(Transport& link, const TransferJob& job, const std::atomic<bool>& cancel,
                       const DripSender::ProgressCallback& progress, const DripSender::LineCallback& line_sent,
                       const PlannedCallback& planned = nullptr);
  /// \brief Stores the program the control punches at job.path (a receive).
  /// \throws ConfigError for a send; the errors of BackupReceiver::receive().
  TransferOutcome backup(Transport& link, const TransferJob& job, const std::atomic<bool>& cancel,
                         const std::function<void(const BackupProgress&)>& progress);

  /// \brief Pauses the running feed (nothing more is sent until resume()); refused if none runs.
  SwitchAnswer pause();
  /// \brief Resumes a paused feed; refused if none runs or it is not paused.
  SwitchAnswer resume();
  /// \brief The plan of a feed of \p file in \p programs from \p restart, with \p restart_preamble
  /// (""; computed) checked. Sends nothing; a failure is the answer.
  DripPlanAnswer plan(const ProgramDirectory& programs, const std::string& file, const RestartPoint& restart,
                      const std::string& restart_preamble) const;

 private:
  /// Makes a running sender reachable from pause() and resume() for the length of one feed.
  class ActiveSender;
  /// The sequence number of line \p number of the file ("" if it has none).
  std::string blockAtLine(const std::string& path, uint64_t number) const;

  const DripSettings settings_;
  std::mutex sender_mutex_;
  DripSender* sender_ = nullptr;  ///< the feed running, for pause() / resume()
};
}  // namespace cnc_bridge::dnc
