// One on/off gate of a node that moves or cuts (safety_switch.h).
#include "cnc_bridge/common/safety_switch.h"

#include <utility>
#include <vector>

namespace cnc_bridge
{
SafetySwitch::SafetySwitch(Names names, bool initial)
    : names_(std::move(names)),
      enabled_(initial),
      last_change_(names_.parameter.empty() ? std::string("start-up value") : "start-up value of " + names_.parameter)
{
}

bool SafetySwitch::set(bool enabled, const std::string& by, const std::string& at)
{
  const std::lock_guard<std::recursive_mutex> gate(gate_);
  bool was = false;
  {
    const std::lock_guard<std::mutex> lock(text_mutex_);
    was = enabled_.exchange(enabled);
    last_change_ = std::string(enabled ? "enabled" : "disabled") + " by " + by + (at.empty() ? "" : " at " + at);
    if (!enabled)
    {
      disabled_by_ = by;
    }
  }
  // A copy: a listener may subscribe another (it runs from the next change on).
  std::vector<Listener> listeners;
  listeners.reserve(listeners_.size());
  for (const auto& entry : listeners_)
  {
    listeners.push_back(entry.second);
  }
  for (const Listener& listener : listeners)
  {
    listener(enabled, by);
  }
  return was;
}

std::string SafetySwitch::disabledBy() const
{
  const std::lock_guard<std::mutex> lock(text_mutex_);
  return disabled_by_;
}

std::string SafetySwitch::lastChange() const
{
  const std::lock_guard<std::mutex> lock(text_mutex_);
  return last_change_;
}

std::string SafetySwitch::refusal(const std::string& action) const
{
  std::string text = action + " refused: " + names_.what + " is disabled";
  if (!names_.service.empty())
  {
    text += "; enable it with " + names_.service + " (std_srvs/SetBool, data: true)";
  }
  if (!names_.parameter.empty())
  {
    text +=
        (names_.service.empty() ? "; start the node with the parameter " : ", or start the node with the parameter ") +
        names_.parameter + " true";
  }
  return text;
}

SafetySwitch::Subscription SafetySwitch::subscribe(Listener listener)
{
  const std::lock_guard<std::recursive_mutex> gate(gate_);
  const Subscription id = next_subscription_++;
  listeners_.emplace(id, std::move(listener));
  return id;
}

void SafetySwitch::unsubscribe(Subscription subscription)
{
  const std::lock_guard<std::recursive_mutex> gate(gate_);
  listeners_.erase(subscription);
}
}  // namespace cnc_bridge
