#!/usr/bin/env python3
"""Run on the cell host: the remote machine's state arrives and its tool frame can be looked up."""
import sys

import rospy
import tf2_ros

from cnc_bridge.msg import MachineState


def main(namespace, prefix):
    rospy.init_node("check_remote_machine")
    state = rospy.wait_for_message(namespace + "/state", MachineState, timeout=30)
    if state.machine != "remote_mill" or state.link != MachineState.LINK_UP:
        print("unexpected state: machine=%r link=%d" % (state.machine, state.link))
        return 1
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    t = buffer.lookup_transform(prefix + "machine", prefix + "tool", rospy.Time(0), rospy.Duration(15))
    p = t.transform.translation
    print("state of %s crossed hosts; tool at (%.3f, %.3f, %.3f) m in %smachine" % (state.machine, p.x, p.y, p.z, prefix))
    return 0 if abs(p.z + 0.3) < 1e-6 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
