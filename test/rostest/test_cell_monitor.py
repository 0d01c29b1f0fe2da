#!/usr/bin/env python3
"""cell_monitor over a simulated Haas NGC and a machine with no node (test/rostest/cell_monitor.test).

The simulated machine loops every 9 s through idle, a cycle (spindle on, feed hold), idle, an alarm,
idle and a dropped connection, so each condition of "safe to enter" breaks in turn. Every wait is
on a message, a service or an action result, with a timeout.
"""
import math
import os
import sys
import unittest

import actionlib
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from cnc_bridge.msg import CellEntryEvent, CellState, CycleCountdown, HoldEntryAction, HoldEntryGoal, MachineState
from cnc_bridge.srv import RequestEntry

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topic_collector import Collector  # noqa: E402

SAFE_EXECUTION = (MachineState.EXECUTION_READY, MachineState.EXECUTION_STOPPED)


def machine(view, name):
    return next(m for m in view.machines if m.machine == name)


class CellMonitorTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_cell_monitor")
        cls.views = Collector("/cell_state", CellState)
        cls.events = Collector("/entry_events", CellEntryEvent)
        cls.diagnostics = Collector("/diagnostics", DiagnosticArray)
        cls.countdowns = Collector("/cycle_countdown", CycleCountdown)
        rospy.wait_for_service("/cell_monitor/request_entry", 30)
        cls.request = rospy.ServiceProxy("/cell_monitor/request_entry", RequestEntry)
        cls.release = rospy.ServiceProxy("/cell_monitor/release_entry", RequestEntry)
        cls.hold = actionlib.SimpleActionClient("/cell_monitor/hold_entry", HoldEntryAction)
        assert cls.hold.wait_for_server(rospy.Duration(30))
        assert cls.events.wait_connected()

    def grant(self, robot):
        """Waits for a safe view of haas_ngc and asks; the machine may turn unsafe in between."""
        for _ in range(10):
            start = self.views.count()
            self.assertIsNotNone(self.views.wait(lambda v: machine(v, "haas_ngc").safe_to_enter, 30, start))
            answer = self.request("haas_ngc", robot)
            if answer.granted:
                return
        self.fail("haas_ngc never granted an entry while it looked safe")

    def test_a_machine_without_state_or_unknown_is_never_entered(self):
        answer = self.request("ghost", "r1")
        self.assertFalse(answer.granted)
        self.assertEqual(answer.reason, "no state received")
        answer = self.request("lathe_9", "r1")
        self.assertFalse(answer.granted)
        self.assertIn("no machine 'lathe_9'", answer.reason)
        self.hold.send_goal(HoldEntryGoal(machine="ghost", robot="r1", timeout=0.5))
        self.assertTrue(self.hold.wait_for_result(rospy.Duration(20)))
        self.assertEqual(self.hold.get_state(), actionlib.GoalStatus.ABORTED)
        self.assertFalse(self.hold.get_result().granted)
        self.assertIn("no state received", self.hold.get_result().reason)
        view = self.views.wait(lambda v: True, 10)
        self.assertFalse(machine(view, "ghost").state_known)
        self.assertFalse(machine(view, "ghost").safe_to_enter)

    def test_b_entry_is_leased_then_withdrawn_when_the_cycle_starts(self):
        self.grant("r1")
        refused = self.request("haas_ngc", "r2")
        self.assertFalse(refused.granted)
        self.assertEqual(refused.reason, "entry held by robot 'r1'")
        withdrawn = self.events.wait(
            lambda e: e.event == CellEntryEvent.WITHDRAWN and e.machine == "haas_ngc" and e.robot == "r1", 30)
        self.assertIsNotNone(withdrawn)
        self.assertTrue(withdrawn.reason)
        error = self.diagnostics.wait(lambda a: any(
            s.level == DiagnosticStatus.ERROR and s.hardware_id == "haas_ngc" and "'r1' withdrawn" in s.message
            for s in a.status), 10)
        self.assertIsNotNone(error)
        # The lease is gone: releasing it is refused.
        self.assertFalse(self.release("haas_ngc", "r1").granted)

    def test_c_hold_entry_waits_until_safe(self):
        # Ask while the machine is not safe, so the goal has to wait.
        start = self.views.count()
        self.assertIsNotNone(self.views.wait(lambda v: not machine(v, "haas_ngc").safe_to_enter, 30, start))
        self.hold.send_goal(HoldEntryGoal(machine="haas_ngc", robot="r2", timeout=30.0))
        self.assertTrue(self.hold.wait_for_result(rospy.Duration(40)))
        self.assertEqual(self.hold.get_state(), actionlib.GoalStatus.SUCCEEDED)
        self.assertTrue(self.hold.get_result().granted)
        self.assertTrue(self.release("haas_ngc", "r2").granted)
        self.assertIsNotNone(self.events.wait(lambda e: e.event == CellEntryEvent.RELEASED and e.robot == "r2", 10))

    def test_d_every_safe_view_meets_every_condition(self):
        # Two full loops of the simulated machine, on top of what the other tests saw.
        start = self.views.count()
        for execution in (MachineState.EXECUTION_ALARM, MachineState.EXECUTION_ACTIVE):
            unsafe = self.views.wait(lambda v: machine(v, "haas_ngc").state.execution == execution, 30, start)
            self.assertIsNotNone(unsafe, "no view with execution %d" % execution)
            self.assertFalse(machine(unsafe, "haas_ngc").safe_to_enter)
        seen_safe = 0
        for view in list(self.views.messages):
            m = machine(view, "haas_ngc")
            if not m.safe_to_enter:
                self.assertTrue(m.reason)
                continue
            seen_safe += 1
            self.assertEqual(m.reason, "")
            self.assertEqual(m.state.link, MachineState.LINK_UP)
            self.assertEqual(m.state.estop, MachineState.ESTOP_OFF)
            self.assertIn(m.state.execution, SAFE_EXECUTION)
            self.assertTrue(math.isfinite(m.state.spindle_speed) and abs(m.state.spindle_speed) < 0.5)
            self.assertFalse(machine(view, "ghost").safe_to_enter)
        self.assertGreater(seen_safe, 0)

    def test_e_time_to_cycle_end(self):
        # haas_ngc runs O00110 (test/data/cell/programs: a 1 s tool change and a 2 s dwell under its
        # cycle_time profile): the machine's 3 s of BUSY, with a feed hold between.
        def haas(c):
            return c.machine == "haas_ngc"
        known = self.countdowns.wait(lambda c: haas(c) and math.isfinite(c.time_to_cycle_end), 30)
        self.assertIsNotNone(known, "no time to cycle end for haas_ngc in a cycle")
        self.assertEqual(known.program, "O00110")
        self.assertAlmostEqual(known.planned_cycle_time, 3.0, places=9)
        # Its first value comes with the cycle's start (at most one state poll and one tick late).
        self.assertLessEqual(known.time_to_cycle_end, 3.0)
        self.assertGreater(known.time_to_cycle_end, 1.0)
        first = self.countdowns.messages.index(known)
        end = self.countdowns.wait(lambda c: haas(c) and math.isnan(c.time_to_cycle_end), 30, first)
        self.assertIsNotNone(end, "the countdown never ended")
        self.assertEqual(end.reason, "no cycle running")
        cycle = [c.time_to_cycle_end for c in self.countdowns.messages[first:self.countdowns.messages.index(end)]
                 if haas(c)]
        self.assertTrue(all(math.isfinite(t) and 0.0 <= t <= 3.0 for t in cycle), cycle)
        self.assertEqual(cycle, sorted(cycle, reverse=True), "the countdown went back up")
        # The machine without a node: never a number, and why.
        ghost = self.countdowns.wait(lambda c: c.machine == "ghost", 10)
        self.assertIsNotNone(ghost)
        self.assertTrue(math.isnan(ghost.time_to_cycle_end))
        self.assertEqual(ghost.reason, "no state received")


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_cell_monitor", CellMonitorTest)
