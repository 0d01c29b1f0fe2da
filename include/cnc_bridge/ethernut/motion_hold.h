// The hold a motion disable puts on a running job is the job runner's (cnc_bridge/common/motion_hold.h).
#pragma once

#include "cnc_bridge/common/motion_hold.h"

namespace cnc_bridge
{
namespace ethernut
{
using cnc_bridge::MotionHold;
}  // namespace ethernut
}  // namespace cnc_bridge
