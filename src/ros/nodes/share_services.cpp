// share_node's services on the share and the archive (src/ros/nodes/share_node.h): listing, removal,
// withdrawals, history, comparison and ~publish_to_machines, each mapped onto the core.
#include "share_node.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <future>
#include <thread>

#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/share/share_service.h"

namespace cnc_bridge
{
namespace
{
/// A service's answer when what it does throws: the error is its message.
template <class Response, class F>
bool answer(Response& response, F f)
{
  try
  {
    f();
  }
  catch (const Error& e)
  {
    response.message = e.what();
  }
  return true;
}
}  // namespace

bool ShareNode::onList(ListPrograms::Request&, ListPrograms::Response& response)
{
  try
  {
    for (const programs::ProgramListing& item : programs::listPrograms(*store_, program_settings_.pattern))
    {
      ProgramInfo info;
      info.name = item.entry.name;
      info.number = share::listedNumber(item);
      info.size = item.entry.size;
      info.mtime = ros::Time(static_cast<uint32_t>(std::max<int64_t>(0, item.entry.mtime)), 0);
      info.comment = item.header.comment;
      response.programs.push_back(info);
    }
    response.success = true;
    response.message = std::to_string(response.programs.size()) + " programs on " + store_->describe();
  }
  catch (const Error& e)
  {
    response.message = e.what();
    if (dynamic_cast<const LinkError*>(&e) != nullptr)
      linkResult(e.what());
  }
  return true;
}

bool ShareNode::onRemove(RemoveProgram::Request& request, RemoveProgram::Response& response)
{
  const share::Answer removed = share::removeProgram(*store_, request.file, settings_.enable_remove);
  response.success = removed.success;
  response.message = removed.message;
  if (removed.success)
    ROS_INFO("%s", removed.message.c_str());
  return true;
}

bool ShareNode::onWithdraw(WithdrawProgram::Request& request, WithdrawProgram::Response& response)
{
  return answer(response,
                [&]
                {
                  const programs::Withdrawal done = programs::withdrawProgram(
                      *store_, *archive_, request.file, {"share_node", program_settings_.machine, "withdrawn"});
                  response.success = done.success;
                  response.message = done.message;
                  response.version = done.version;
                });
}

programs::WithdrawalSummary ShareNode::withdrawAll(const std::string& source)
{
  return programs::withdrawAllPrograms(
      *store_, *archive_, {"share_node", program_settings_.machine, "withdrawn"}, source,
      [&](const programs::Withdrawal& outcome)
      { withdrawals_pub_.publish(event(source, "WITHDRAW", outcome.program, outcome.success, outcome.message)); });
}

bool ShareNode::onWithdrawAll(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
{
  const programs::WithdrawalSummary summary = withdrawAll("~withdraw_all");
  response.success = summary.success;
  response.message = summary.message;
  return true;
}

bool ShareNode::onHistory(ProgramHistory::Request& request, ProgramHistory::Response& response)
{
  return answer(response,
                [&]
                {
                  for (const programs::ArchiveVersion& v : archive_->history(request.file))
                  {
                    ProgramVersion version;
                    version.number = v.number;
                    version.stamp = ros::Time(static_cast<uint32_t>(std::max<int64_t>(0, v.time)), 0);
                    version.node = v.source.node;
                    version.machine = v.source.machine;
                    version.direction = v.source.direction;
                    version.size = v.size;
                    version.crc32 = v.crc32;
                    response.versions.push_back(version);
                  }
                  response.success = true;
                  response.message = std::to_string(response.versions.size()) + " versions of " + request.file +
                                     " in " + archive_->root();
                });
}

bool ShareNode::onCompare(ComparePrograms::Request& request, ComparePrograms::Response& response)
{
  return answer(response,
                [&]
                {
                  response.diff = programs::compareVersions(*archive_, request.file, request.from, request.to,
                                                            share::currentFile(programs_->root(), request.file));
                  response.success = true;
                  response.message = response.diff.empty() ? "identical" : "different";
                });
}

std::string ShareNode::sendThrough(const std::string& machine, const std::string& file)
{
  const std::vector<std::string> services = share::sendProgramServices(nh_.resolveName(machine));
  const auto found = std::find_if(services.begin(), services.end(),
                                  [](const std::string& service) { return ros::service::exists(service, false); });
  if (found == services.end())
    throw LinkError("no machine answers at " + services[0] + " nor " + services[1] +
                    ": is its share_node running, and is the name right?");
  const std::string service = *found;
  // roscpp service calls have no timeout: the call runs on a thread of its own, which a machine
  // that never answers leaves behind until its connection closes.
  auto answer = std::make_shared<std::promise<std::optional<SendProgram::Response>>>();
  std::future<std::optional<SendProgram::Response>> result = answer->get_future();
  std::thread(
      [service, file, answer]
      {
        SendProgram call;
        call.request.file = file;
        if (ros::service::call(service, call))
          answer->set_value(call.response);
        else
          answer->set_value(std::nullopt);
      })
      .detach();
  if (result.wait_for(std::chrono::duration<double>(settings_.publish_timeout)) != std::future_status::ready)
  {
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%g", settings_.publish_timeout);
    throw TimeoutError("no answer from " + service + " within " + seconds +
                       " s (~publish_timeout); the send may still finish there");
  }
  const std::optional<SendProgram::Response> response = result.get();
  if (!response)
    throw LinkError("the call of " + service + " failed: its share_node stopped or refused the connection");
  if (!response->success)
    throw Error(response->message);
  return response->message;
}

bool ShareNode::onPublishToMachines(FanOutProgram::Request& request, FanOutProgram::Response& response)
{
  const auto results = programs::fanOut(
      request.machines, [&](const std::string& machine) { return sendThrough(machine, request.file); },
      [&](const programs::TargetResult& result)
      {
        response.machines.push_back(result.target);
        response.succeeded.push_back(result.success);
        response.messages.push_back(result.message);
        if (result.success)
          ROS_INFO("publish %s to %s: %s", request.file.c_str(), result.target.c_str(), result.message.c_str());
        else
          ROS_ERROR("publish %s to %s failed: %s", request.file.c_str(), result.target.c_str(), result.message.c_str());
      });
  response.success = programs::allSucceeded(results);
  response.message = share::fanOutSummary(results, request.file);
  return true;
}

}  // namespace cnc_bridge
