// Fan-out: one program published to several machines (shares, or share_nodes), each machine's
// result kept on its own, so that one machine that is down does not stop the others. Used by
// `cnc_dnc send --share A --share B` and by share_node's ~publish_to_machines.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace cnc_bridge::programs
{
/// \brief What became of one machine of a fan-out.
struct TargetResult
{
  std::string target;  ///< as given: a share's address, a node's name
  bool success = false;
  std::string message;  ///< the action's result line, or the error that stopped it
};

/// \brief Runs \p publish for each target, one after the other. \p publish returns the result
/// line of a success and throws cnc_bridge::Error for a failure; a failure is that target's result
/// and the next target runs anyway. A CancelledError (the user stopped the whole run) is not a
/// target's failure and propagates. \p report, if given, sees each result as soon as it is known.
std::vector<TargetResult> fanOut(const std::vector<std::string>& targets,
                                 const std::function<std::string(const std::string& target)>& publish,
                                 const std::function<void(const TargetResult&)>& report = nullptr);

/// \returns true when every target succeeded (and there was at least one).
bool allSucceeded(const std::vector<TargetResult>& results);
}  // namespace cnc_bridge::programs
