// A scripted machine as an MTConnect device (see sim_device.h).
#include "sim/mtconnect/sim_device.h"

namespace cnc_bridge
{
namespace mtconnect
{
namespace
{
Mode modeOf(const std::string& mode)
{
  if (mode == "MEM")
    return Mode::kAuto;
  if (mode == "MDI")
    return Mode::kMdi;
  if (mode == "JOG" || mode == "ZERO RET")
    return Mode::kManual;
  if (mode == "EDIT")
    return Mode::kEdit;
  return Mode::kUnknown;
}

Execution executionOf(const std::string& status)
{
  if (status == "IDLE")
    return Execution::kReady;
  if (status == "BUSY")
    return Execution::kActive;
  if (status == "FEED HOLD")
    return Execution::kPaused;
  if (status == "ALARM")
    return Execution::kAlarm;
  return Execution::kUnknown;
}
}  // namespace

MachineReport reportOf(const mdc::SimMachine::State& state, bool inch)
{
  MachineReport report;
  report.link_up = true;
  MachineView& view = report.view;
  view.estop = Tristate::kOff;
  view.mode = modeOf(state.mode);
  view.execution = executionOf(state.status);
  view.program = state.program;
  view.part_count = state.parts;
  view.tool = state.tool;
  const double metres = inch ? 0.0254 : 0.001;
  view.position = {state.x * metres, state.y * metres, state.z * metres};
  view.spindle_rpm = state.spindle;
  if (view.execution == Execution::kAlarm)
    report.message = "ALARM";
  return report;
}
}  // namespace mtconnect
}  // namespace cnc_bridge
