// A scripted machine (mdc::SimMachine, the timeline behind sim_haas_mdc) as an MTConnect device:
// its state at a moment as the report the SHDR adapter core publishes. sim_mtconnect serves it to
// the reference agent, so that the demo cell has a machine reached only through MTConnect. ROS-free.
#pragma once

#include "cnc_bridge/mtconnect/shdr.h"
#include "sim/mdc/sim_machine.h"

namespace cnc_bridge
{
namespace mtconnect
{
/// \brief The report of a scripted machine in state \p state, whose script gives positions in
/// inches when \p inch (else millimetres). Mode: MEM AUTO, MDI, JOG and ZERO RET MANUAL, EDIT;
/// status: IDLE READY, BUSY ACTIVE, FEED HOLD PAUSED, ALARM an alarm (a FAULT with the words
/// "ALARM"). E-stop released, positions ACTUAL in m, spindle rev/min; commanded position and feed
/// unknown (the script does not tell them).
MachineReport reportOf(const mdc::SimMachine::State& state, bool inch);
}  // namespace mtconnect
}  // namespace cnc_bridge
