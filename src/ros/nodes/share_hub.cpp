// share_node's hybrid share (docs/share_node.md, "Hybrid share"): the core's DropFolder and
// Collection (cnc_bridge/share/hybrid_share.h) on the node's own share as the NAS, polled on a
// timer (one of the node's callback threads: a push to a slow machine does not hold its services),
// each result published on hub_events, kept in <archive>/hub_results.log and counted in the
// diagnostics.
#include <diagnostic_updater/diagnostic_updater.h>

#include <ctime>
#include <filesystem>
#include <fstream>
#include <mutex>

#include "cnc_bridge/share/hybrid_share.h"
#include "cnc_bridge/share/smb_store.h"
#include "share_node.h"

namespace cnc_bridge
{
class ShareHub
{
 public:
  ShareHub(ros::NodeHandle nh, const share::StoreSettings& store, const share::HubSettings& hub,
           const share::ProgramSettings& programs, programs::ProgramArchive& archive)
      : log_path_(archive.root() + "/hub_results.log"), pattern_(programs.pattern)
  {
    share::HubRules rules{programs.pattern, programs.protected_range, hub.settle};
    nas_address_ = share::shownAddress(store.address);
    if (!hub.drop_to.empty())
    {
      drop_ = std::make_unique<share::DropFolder>(
          share::openStore(store.address, store.credentials_file, store.timeout), machines(store, hub.drop_to, ""),
          rules, [this](const share::HubResult& r) { record("DROP", "~drop_to", r); });
    }
    if (!hub.collect_from.empty())
    {
      collection_ = std::make_unique<share::Collection>(machines(store, hub.collect_from, store.address), rules,
                                                        archive, programs::VersionSource{"share_node", "", "collected"},
                                                        [this](const std::string&, const share::HubResult& r)
                                                        { record("COLLECT", "~collect_from", r); });
    }
    events_pub_ = nh.advertise<ProgramRequestEvent>("hub_events", 50);
    timer_ = nh.createWallTimer(ros::WallDuration(hub.period), &ShareHub::poll, this);
  }

  ShareHub(const ShareHub&) = delete;
  ShareHub& operator=(const ShareHub&) = delete;

  void diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    status.add("hub: NAS", nas_address_);
    status.add("hub: programs pushed", pushed_);
    status.add("hub: programs collected", collected_);
    status.add("hub: failures", failures_);
    status.add("hub: last failure", last_failure_);
    status.add("hub: last poll error", poll_error_);
    if (!poll_error_.empty())
      status.mergeSummary(diagnostic_updater::DiagnosticStatusWrapper::ERROR, "hybrid share: " + poll_error_);
    else if (failures_ > 0)
      status.mergeSummary(diagnostic_updater::DiagnosticStatusWrapper::WARN, "hybrid share: " + last_failure_);
  }

 private:
  /// Each machine's store; with \p collect_into set (the NAS address), also its NAS folder, made
  /// when the NAS is a local folder (an SMB client cannot make one: it must exist on the server).
  std::vector<share::HubMachine> machines(const share::StoreSettings& store,
                                          const std::map<std::string, std::string>& shares,
                                          const std::string& collect_into)
  {
    std::vector<share::HubMachine> list;
    for (const auto& [name, address] : shares)
    {
      share::HubMachine machine{name, share::openStore(address, store.credentials_file, store.timeout), nullptr};
      if (!collect_into.empty())
      {
        const std::string folder = collect_into + "/" + name;
        if (folder.rfind("smb://", 0) != 0)
          std::filesystem::create_directories(folder);
        machine.collected_into = share::openStore(folder, store.credentials_file, store.timeout);
      }
      list.push_back(std::move(machine));
    }
    return list;
  }

  void poll(const ros::WallTimerEvent&)
  {
    const auto now = share::HubClock::now();
    std::string error;
    try
    {
      if (drop_)
        drop_->poll(now);
    }
    catch (const Error& e)
    {
      error = std::string("cannot list the NAS ") + nas_address_ + ": " + e.what();
    }
    if (collection_)
      collection_->poll(now);
    std::lock_guard<std::mutex> lock(mutex_);
    if (error != poll_error_ && !error.empty())
      ROS_ERROR("%s (nothing pushed until it answers)", error.c_str());
    poll_error_ = error;
  }

  /// One program's result: an event per machine, a line per machine in the log, the counts.
  void record(const std::string& request, const std::string& source, const share::HubResult& result)
  {
    if (programs::allSucceeded(result.machines))
      ROS_INFO_STREAM(share::describe(result));
    else
      ROS_WARN_STREAM(share::describe(result));
    std::ofstream log(log_path_, std::ios::app);
    for (const auto& machine : result.machines)
    {
      ProgramRequestEvent event;
      event.header.stamp = ros::Time::now();
      event.machine = machine.target;
      event.source = source;
      event.request = request;
      event.program = result.program;
      event.number = pattern_.number(result.program).value_or(0);
      event.success = machine.success;
      event.outcome = machine.message;
      events_pub_.publish(event);
      log << std::to_string(std::time(nullptr)) << '\t' << request << '\t' << result.program << '\t' << machine.target
          << '\t' << (machine.success ? "ok" : "FAILED") << '\t' << machine.message << '\n';
      std::lock_guard<std::mutex> lock(mutex_);
      if (!machine.success)
      {
        ++failures_;
        last_failure_ = result.program + " " + machine.target + ": " + machine.message;
      }
      else
        ++(request == "DROP" ? pushed_ : collected_);
    }
  }

  std::string log_path_;
  programs::NamePattern pattern_;
  std::string nas_address_;
  std::unique_ptr<share::DropFolder> drop_;
  std::unique_ptr<share::Collection> collection_;
  ros::Publisher events_pub_;
  ros::WallTimer timer_;
  std::mutex mutex_;
  unsigned pushed_ = 0, collected_ = 0, failures_ = 0;
  std::string last_failure_, poll_error_;
};

std::shared_ptr<ShareHub> startShareHub(ros::NodeHandle nh, const share::StoreSettings& store,
                                        const share::HubSettings& hub, const share::ProgramSettings& programs,
                                        programs::ProgramArchive& archive, MachineStatePublisher& state)
{
  if (!hub.enabled())
    return nullptr;
  auto started = std::make_shared<ShareHub>(nh, store, hub, programs, archive);
  state.diagnostics().add("Hybrid share", started.get(), &ShareHub::diagnostics);
  ROS_INFO("share_node: hybrid share: %zu machine(s) to push to, %zu to collect from", hub.drop_to.size(),
           hub.collect_from.size());
  return started;
}
}  // namespace cnc_bridge
