// The section-6 sequencing rules of the '@'-protocol (see sequencer.h).
#include "cnc_bridge/at_protocol/sequencer.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace at_protocol
{
const char* toString(Phase phase)
{
  switch (phase)
  {
    case Phase::kIdle:
      return "idle";
    case Phase::kMachining:
      return "machining";
    case Phase::kOperation:
      return "operation";
  }
  return "?";
}

std::string Sequencer::refusal(const Command& command) const
{
  const std::string what = describe(command);
  if (std::holds_alternative<JogMode>(command) || std::holds_alternative<JogFeed>(command) ||
      std::holds_alternative<Home>(command))
  {
    return phase_ == Phase::kIdle ? "" : what + " refused while machining (between M1@ and M0@)";
  }
  if (const auto* machining = std::get_if<Machining>(&command))
  {
    if (machining->start)
    {
      return phase_ == Phase::kIdle ? "" : what + " refused: machining already started";
    }
    if (phase_ == Phase::kOperation)
    {
      return what + " refused: the operation in progress must end with #@ first";
    }
    return phase_ == Phase::kMachining ? "" : what + " refused: no machining in progress (M1@ not sent)";
  }
  if (std::holds_alternative<StartOperation>(command))
  {
    if (phase_ == Phase::kIdle)
    {
      return what + " refused: machining not started (send M1@ first)";
    }
    return phase_ == Phase::kMachining ? "" : what + " refused: an operation is already in progress";
  }
  if (std::holds_alternative<Setpoint>(command) || std::holds_alternative<EndOperation>(command))
  {
    return phase_ == Phase::kOperation ? "" : what + " refused: no operation in progress (send P0@ or P1@ first)";
  }
  if (std::holds_alternative<ToolChange>(command))
  {
    return phase_ == Phase::kOperation && moved_in_operation_ ? what + " refused: the operation is already moving" : "";
  }
  return "";  // A@, S@
}

void Sequencer::apply(const Command& command)
{
  const std::string why = refusal(command);
  if (!why.empty())
  {
    throw ProtocolError(why);
  }
  if (const auto* jog = std::get_if<JogMode>(&command))
  {
    jog_axis_ = jog->axis;
    auto_mode_ = false;
  }
  else if (std::holds_alternative<AutoMode>(command))
  {
    jog_axis_.reset();
    auto_mode_ = true;
  }
  else if (const auto* feed = std::get_if<JogFeed>(&command))
  {
    jog_feed_ = feed->feed;
  }
  else if (const auto* machining = std::get_if<Machining>(&command))
  {
    phase_ = machining->start ? Phase::kMachining : Phase::kIdle;
    if (!machining->start)
    {
      spindle_ = 0;
    }
  }
  else if (const auto* operation = std::get_if<StartOperation>(&command))
  {
    phase_ = Phase::kOperation;
    coolant_ = operation->coolant;
    moved_in_operation_ = false;
  }
  else if (std::holds_alternative<Setpoint>(command))
  {
    moved_in_operation_ = true;
  }
  else if (std::holds_alternative<EndOperation>(command))
  {
    phase_ = Phase::kMachining;
    coolant_ = false;
  }
  else if (const auto* spindle = std::get_if<Spindle>(&command))
  {
    spindle_ = spindle->speed;
  }
  else if (const auto* tool = std::get_if<ToolChange>(&command))
  {
    tool_ = tool->tool;
  }
}

void Sequencer::reset()
{
  phase_ = Phase::kIdle;
  coolant_ = false;
  moved_in_operation_ = false;
  spindle_ = 0;
}
}  // namespace at_protocol
}  // namespace cnc_bridge
