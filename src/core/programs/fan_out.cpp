#include "cnc_bridge/programs/fan_out.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::programs
{
std::vector<TargetResult> fanOut(const std::vector<std::string>& targets,
                                 const std::function<std::string(const std::string& target)>& publish,
                                 const std::function<void(const TargetResult&)>& report)
{
  std::vector<TargetResult> results;
  results.reserve(targets.size());
  for (const std::string& target : targets)
  {
    TargetResult result;
    result.target = target;
    try
    {
      result.message = publish(target);
      result.success = true;
    }
    catch (const CancelledError&)
    {
      throw;
    }
    catch (const Error& e)
    {
      result.message = e.what();
    }
    if (report)
      report(result);
    results.push_back(std::move(result));
  }
  return results;
}

bool allSucceeded(const std::vector<TargetResult>& results)
{
  return !results.empty() &&
         std::all_of(results.begin(), results.end(), [](const TargetResult& result) { return result.success; });
}
}  // namespace cnc_bridge::programs
