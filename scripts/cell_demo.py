#!/usr/bin/env python3
"""The scripted scenario of the simulated cell: what a robot cell's orchestration code would do.

Waits for every machine of the cell description, then, for each node a machine runs:
  dnc_node         sends a program to the control by XModem (~transfer action); where the node
                   may move the machine (enable_motion: a Fanuc in DNC mode), drip-feeds one and
                   reports the commanded positions it published during the feed
  dprnt_node       waits for the probe grid the macro program prints; surface_mapper saves the map
  ethernut_node    streams a G-code job to the board (~run_job action)
  at_controller    follows a G-code path with 1 ms setpoints (~follow_path action)
  slave_bus_node   steps the bus: axes move, the tool toggles
  haas_mdc_node    reports the cycle events it saw (a robot waits for CYCLE_END to unload)
  mtconnect_node   a machine reached only through its MTConnect agent: waits for a whole cycle
                   read from the agent's stream, and reports its cycle events
Once the machines are up, it reads what mtconnect_adapter_node (the cell's machines out to the
shop's MTConnect agent) serves, as an agent connecting to it does, and prints every machine's line.
Before each of these steps the cell's robot (a stand-in) asks cell_monitor whether it may enter the
machine and prints the answer with its reason,
while the '@' router follows its path it prints cell_monitor's countdown to the cycle end (at the
start, halfway, at the end) and the predicted against the actual cycle, once the countdown of a
machine whose time to cycle end is not known, with the reason,
and prints a readable line for everything that happens, with numbers. Exit status 0 only if
every step succeeded. Then, unless --once, keeps printing the cell's state until Ctrl-C.

  cell_demo.py --cell config/cell.yaml --output DIR --programs DIR
"""
import argparse
import logging
import math
import os
import re
import shutil
import socket
import sys
import threading
import time

import actionlib
import rospy
import rosgraph
import yaml
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import PointCloud2

from cnc_bridge.msg import (AtFollowPathAction, AtFollowPathGoal, CellState, CycleCountdown, CycleEvent,
                            MachineState, RunJobAction, RunJobGoal, SlaveCommand, SlaveResponse, TransferAction,
                            TransferGoal)
from cnc_bridge.srv import DprntSaveSurface, RequestEntry

MODES = {v: k[5:] for k, v in vars(MachineState).items() if k.startswith("MODE_")}
EXECUTION = {v: k[10:] for k, v in vars(MachineState).items() if k.startswith("EXECUTION_")}
LINK = {v: k[5:] for k, v in vars(MachineState).items() if k.startswith("LINK_")}
EVENTS = {v: k for k, v in vars(CycleEvent).items() if k.isupper() and isinstance(v, int)}


SAY_LOCK = threading.Lock()  # the steps run side by side: one whole line at a time


def say(text):
    with SAY_LOCK:
        print("[%7.2f s] %s" % (time.time() - START, text), flush=True)


def describe(state):
    position = ""
    if state.position_valid:
        p = state.position
        position = " at (%.1f, %.1f, %.1f) mm" % (p.x * 1e3, p.y * 1e3, p.z * 1e3)
    extra = []
    if state.program:
        extra.append("program %s" % state.program)
    if state.part_count >= 0:
        extra.append("parts %d" % state.part_count)
    if state.message:
        extra.append(state.message)
    return "link %s, %s, %s%s%s" % (LINK.get(state.link, "?"), MODES.get(state.mode, "?"),
                                    EXECUTION.get(state.execution, "?"), position,
                                    ("; " + "; ".join(extra)) if extra else "")


class Machine:
    """One machine of the cell: its namespace, nodes and last states."""

    def __init__(self, cell, entry):
        self.name = entry["name"]
        self.ns = "/%s/%s" % (cell, self.name)
        self.nodes = {node["launch"]: node for node in entry.get("nodes", [])}
        self.states = {}
        self.events = []
        self.cycle_ended = threading.Event()  # a whole cycle (start and end) was seen
        self.lock = threading.Lock()
        self.subscribers = []
        for node in entry.get("nodes", []):
            topic = node.get("remap", {}).get("state", "state")
            if node["launch"] == "surface_mapper":
                continue
            self.subscribers.append(rospy.Subscriber(self.ns + "/" + topic, MachineState, self._on_state,
                                                     callback_args=node["launch"]))
        if "haas_mdc_node" in self.nodes or "mtconnect_node" in self.nodes:
            self.subscribers.append(rospy.Subscriber(self.ns + "/events", CycleEvent, self._on_event))

    def _on_state(self, state, node):
        with self.lock:
            self.states[node] = state

    def _on_event(self, event):
        with self.lock:
            self.events.append(event)
        if event.event == CycleEvent.CYCLE_END and math.isfinite(event.cycle_time):
            self.cycle_ended.set()
        say("%s: %s %s%s" % (self.name, EVENTS.get(event.event, "?"), event.program,
                             (", parts %d" % event.part_count) if event.part_count >= 0 else ""))

    def wait_up(self, timeout):
        deadline = time.time() + timeout
        while time.time() < deadline and not rospy.is_shutdown():
            with self.lock:
                up = [n for n, s in self.states.items() if s.link == MachineState.LINK_UP]
                missing = [n for n in self.nodes if n != "surface_mapper" and n not in self.states]
            if not missing and (up or not self.states):
                return True
            time.sleep(0.2)
        return False


class UntrackedTransitionFilter(logging.Filter):
    """rospy's SimpleActionClient can see the server's first status before send_goal() has stored
    the goal handle, logs "Got a transition callback on a goal handle that we're not tracking" and
    carries on correctly (ros/actionlib#206). The steps here run side by side, which makes it
    frequent: keep it out of the demo's output."""

    def filter(self, record):
        return "goal handle that we're not tracking" not in record.getMessage()


# Subscribers a goal or command publisher waits for besides the node: the rosbag recorder
# (--recorded), which finds new topics only when it next polls the master; a goal published
# before it subscribed would be missing from the bag.
RECORDERS = 0


def wait_subscribers(publisher, count, what, timeout=10.0):
    deadline = time.time() + timeout
    while publisher.get_num_connections() < count:
        if time.time() > deadline:
            raise RuntimeError("%s: %d of %d subscribers within %.0f s" % (
                what, publisher.get_num_connections(), count, timeout))
        time.sleep(0.05)


def action(ns, name, action_type, goal, timeout, feedback=None):
    client = actionlib.SimpleActionClient(ns + "/" + name, action_type)
    if not client.wait_for_server(rospy.Duration(20)):
        raise RuntimeError("no action server %s/%s" % (ns, name))
    wait_subscribers(client.action_client.pub_goal, 1 + RECORDERS, "%s/%s/goal" % (ns, name))
    client.send_goal(goal, feedback_cb=feedback)
    if not client.wait_for_result(rospy.Duration(timeout)):
        client.cancel_goal()
        raise RuntimeError("%s/%s did not finish within %d s" % (ns, name, timeout))
    return client.get_result()


class Progress:
    """Prints feedback at 25 % steps, not every message."""

    def __init__(self, label, percent_of):
        self.label, self.percent_of, self.next = label, percent_of, 25

    def __call__(self, feedback):
        percent = self.percent_of(feedback)
        if percent >= self.next:
            say("%s %3.0f %%" % (self.label, percent))
            while self.next <= percent:
                self.next += 25


def send_program(machine, args):
    if machine.nodes["dnc_node"].get("args", {}).get("enable_motion"):
        return drip_feed(machine, args)  # the control runs the program as it is fed (DNC)
    program = args.program
    shutil.copy(program, os.path.join(args.programs, os.path.basename(program)))
    goal = TransferGoal(direction="send", protocol="xmodem", file=os.path.basename(program))
    started = time.time()
    result = action(machine.ns + "/dnc_node", "transfer", TransferAction, goal, 300,
                    Progress("%s: XModem send" % machine.name, lambda f: f.percent))
    elapsed = time.time() - started
    if not result.success:
        raise RuntimeError(result.message)
    say("%s: sent %s by XModem: %d bytes, %d blocks, %d retries in %.1f s (%s)" % (
        machine.name, goal.file, result.bytes, result.blocks, result.retries, elapsed, result.message))


def wait_topic_subscribers(subscriber, count, timeout=10.0):
    """Until this subscriber is connected to the topic's publisher and the master lists `count`
    subscribers of it (this one and the rosbag recorder's, which finds topics when it polls)."""
    master = rosgraph.Master(rospy.get_name())
    deadline = time.time() + timeout
    while True:
        listed = dict(master.getSystemState()[1]).get(subscriber.resolved_name, [])
        if subscriber.get_num_connections() >= 1 and len(listed) >= count:
            return
        if time.time() > deadline:
            raise RuntimeError("%s: %d connections, %d of %d subscribers within %.0f s" % (
                subscriber.resolved_name, subscriber.get_num_connections(), len(listed), count, timeout))
        time.sleep(0.05)


def drip_feed(machine, args):
    """Drip-feeds --drip-program through dnc_node's ~transfer action (protocol drip) and reports the
    commanded positions the node published on dnc/commanded_position during the feed (the end of
    the last motion block fed, in the program's coordinates: ahead of the tool, which the control's
    buffer keeps behind)."""
    if not args.drip_program:
        raise RuntimeError("no --drip-program for the drip-feed")
    file = os.path.basename(args.drip_program)
    shutil.copy(args.drip_program, os.path.join(args.programs, file))
    seen = []
    sub = rospy.Subscriber(machine.ns + "/dnc/commanded_position", PointStamped, seen.append)
    try:
        wait_topic_subscribers(sub, 1 + RECORDERS)
        goal = TransferGoal(direction="send", protocol="drip", file=file)
        started = time.time()
        result = action(machine.ns + "/dnc_node", "transfer", TransferAction, goal, 120,
                        Progress("%s: drip-feed" % machine.name, lambda f: f.percent))
        elapsed = time.time() - started
    finally:
        sub.unregister()
    if not result.success:
        raise RuntimeError(result.message)
    if not seen:
        raise RuntimeError("no commanded position on %s during the feed" % sub.resolved_name)
    distinct = len({(p.point.x, p.point.y, p.point.z) for p in seen})
    last = seen[-1]
    say("%s: drip-fed %s: %d bytes in %.1f s, to line %d; %d commanded positions (%d distinct), "
        "the last (%.3f, %.3f, %.3f) mm in %s" % (
            machine.name, file, result.bytes, elapsed, result.stopped_at_line, len(seen), distinct,
            last.point.x * 1e3, last.point.y * 1e3, last.point.z * 1e3, last.header.frame_id))


def probe_surface(machine, args):
    output = args.output
    points = {"n": 0}
    done = threading.Event()

    def on_cloud(cloud):
        points["n"] = cloud.width * cloud.height
        if points["n"] >= args.grid_points:
            done.set()

    sub = rospy.Subscriber(machine.ns + "/surface/cloud", PointCloud2, on_cloud)
    say("%s: waiting for the probe grid printed by DPRNT (%d points)" % (machine.name, args.grid_points))
    if not done.wait(args.timeout):
        sub.unregister()
        raise RuntimeError("only %d of %d probe points arrived" % (points["n"], args.grid_points))
    sub.unregister()
    service = machine.ns + "/surface_mapper/save"
    rospy.wait_for_service(service, 10)
    result = rospy.ServiceProxy(service, DprntSaveSurface)(name=machine.name + "_surface")
    if not result.success:
        raise RuntimeError(result.message)
    for path in (result.png_path, result.csv_path):
        if os.path.dirname(os.path.abspath(path)) != os.path.abspath(output):
            shutil.copy(path, output)
    say("%s: surface map of %d points: z %.4f .. %.4f mm, flatness %.4f mm (rms %.4f mm) -> %s" % (
        machine.name, result.points, result.min_z * 1e3, result.max_z * 1e3, result.flatness * 1e3,
        result.rms_deviation * 1e3, os.path.join(output, os.path.basename(result.png_path))))


def run_job(machine, args):
    shutil.copy(args.job, os.path.join(args.programs, os.path.basename(args.job)))
    goal = RunJobGoal(file=os.path.basename(args.job))
    started = time.time()
    result = action(machine.ns + "/ethernut_node", "run_job", RunJobAction, goal, 300,
                    Progress("%s: job" % machine.name, lambda f: f.percent))
    if not result.success:
        raise RuntimeError(result.message)
    say("%s: job %s streamed: %d/%d coordinates, %d resends in %.1f s" % (
        machine.name, goal.file, result.coordinates_done, result.coordinate_count, result.resends,
        time.time() - started))


def follow_path(machine, args):
    shutil.copy(args.path_program, os.path.join(args.programs, os.path.basename(args.path_program)))
    goal = AtFollowPathGoal(gcode_file=os.path.basename(args.path_program), coolant=-1, tool=-1)
    cycle = CycleFollow(machine, goal.gcode_file) if COUNTDOWNS else None
    started = time.time()
    try:
        result = action(machine.ns + "/at_controller_node", "follow_path", AtFollowPathAction, goal, 300,
                        Progress("%s: path" % machine.name, lambda f: 100.0 * f.progress))
    finally:
        if cycle:
            cycle.finish()
    if not result.success:
        raise RuntimeError(result.message)
    p = result.final_position
    # final_position: the controller's report of the end point, which ended the goal; the result's
    # message says which end point and how far from it ("... (1 um from it) 0.018 s after ...").
    confirmed = re.search(r"the controller reported the end point .*", result.message)
    say("%s: path followed: %d setpoints at 1 kHz, %d late, in %.1f s; ends at (%.3f, %.3f, %.3f) mm "
        "as the controller reported it%s" % (
            machine.name, result.setpoints, result.underruns, time.time() - started, p.x * 1e3, p.y * 1e3,
            p.z * 1e3, ": " + confirmed.group(0) if confirmed else ""))


# cell_monitor's time to cycle end (docs/cell_monitor.md), for the machines with a `cycle_time`
# entry in the cell file; None when the cell has no cell_monitor.
COUNTDOWN_TOPIC = "/cycle_countdown"
COUNTDOWNS = None


class Countdowns:
    """cell_monitor's cycle_countdown: handed to the machine's follower while one listens, else
    printed once per machine whose countdown in a cycle is not known, with the reason."""

    def __init__(self):
        self.lock = threading.Lock()
        self.followers, self.told = {}, set()
        self.sub = rospy.Subscriber(COUNTDOWN_TOPIC, CycleCountdown, self._on_countdown)

    def follow(self, machine, callback):
        with self.lock:
            self.followers[machine] = callback

    def _on_countdown(self, countdown):
        with self.lock:
            follower = self.followers.get(countdown.machine)
            tell = (follower is None and countdown.program and math.isnan(countdown.time_to_cycle_end)
                    and countdown.machine not in self.told)
            if tell:
                self.told.add(countdown.machine)
        if follower:
            follower(countdown)
        elif tell:
            say("%s: cycle of %s: time to cycle end not known: %s" % (
                countdown.machine, countdown.program, countdown.reason))


class CycleFollow:
    """One machine's cycle of one program: cell_monitor's countdown at its start, halfway and end,
    and the planned cycle against the actual one (the machine's state ACTIVE until it leaves it)."""

    def __init__(self, machine, program):
        self.machine, self.program = machine, program
        self.lock = threading.Lock()
        self.first = self.last = None  # known countdowns
        self.halfway_told = False
        self.active_since = self.active_for = None
        self.ended = threading.Event()
        self.state_sub = rospy.Subscriber(machine.ns + "/state", MachineState, self._on_state)
        COUNTDOWNS.follow(machine.name, self._on_countdown)

    def _line(self, countdown):
        return "%s: cycle of %s: %.1f s planned, %.1f s to go" % (
            self.machine.name, countdown.program, countdown.planned_cycle_time, countdown.time_to_cycle_end)

    def _on_countdown(self, countdown):
        if countdown.program != self.program or math.isnan(countdown.time_to_cycle_end):
            return
        with self.lock:
            first = self.first is None
            halfway = (not first and not self.halfway_told
                       and countdown.time_to_cycle_end <= countdown.planned_cycle_time / 2)
            self.first = self.first or countdown
            self.last = countdown
            self.halfway_told = self.halfway_told or halfway
        if first or halfway:
            say(self._line(countdown))

    def _on_state(self, state):
        now = time.time()  # as received: the state comes at the node's state_rate (10 Hz)
        with self.lock:
            if self.active_since is None:
                if state.execution == MachineState.EXECUTION_ACTIVE and state.program == self.program:
                    self.active_since = now
            elif self.active_for is None and state.execution not in (MachineState.EXECUTION_ACTIVE,
                                                                        MachineState.EXECUTION_PAUSED):
                self.active_for = now - self.active_since
                self.ended.set()

    def finish(self):
        self.ended.wait(5.0)  # the state that ends the cycle may come just after the action's result
        self.state_sub.unregister()
        COUNTDOWNS.follow(self.machine.name, None)
        with self.lock:
            first, last, actual = self.first, self.last, self.active_for
        if last is None:
            say("%s: cycle of %s: no countdown from cell_monitor" % (self.machine.name, self.program))
            return
        if last is not first:
            say(self._line(last))
        if actual is None:
            say("%s: cycle of %s: its end was not seen in the machine's state" % (self.machine.name, self.program))
            return
        planned = last.planned_cycle_time
        say("%s: cycle of %s ended: predicted %.1f s, actual %.1f s (%+.1f %%)" % (
            self.machine.name, self.program, planned, actual, 100.0 * (planned - actual) / actual))


def step_bus(machine, args):
    responses = []
    sub = rospy.Subscriber(machine.ns + "/slaves/x/response", SlaveResponse, responses.append)
    axes = {axis: rospy.Publisher(machine.ns + "/slaves/%s/command" % axis, SlaveCommand, queue_size=10)
            for axis in ("x", "y", "z", "laser")}
    # Commands published before the node (and the recorder) have connected to these new
    # publishers would be lost.
    for axis, pub in axes.items():
        wait_subscribers(pub, 1 + RECORDERS, "slaves/%s/command" % axis)
    corners = [(0.15, 0.0), (0.15, 0.15), (0.0, 0.15), (0.0, 0.0)]
    for number, (x, y) in enumerate(corners):
        # One step: every axis and the laser in the same frame (the node queues commands
        # published together into one frame), the laser on while cutting the square's sides.
        axes["x"].publish(SlaveCommand(values=[x]))
        axes["y"].publish(SlaveCommand(values=[y]))
        axes["z"].publish(SlaveCommand(values=[0.0]))
        axes["laser"].publish(SlaveCommand(values=[1 if number < len(corners) - 1 else 0]))
        deadline = time.time() + 10
        while time.time() < deadline:
            state = machine.states.get("slave_bus_node")
            if state and state.position_valid and abs(state.position.x - x) < 1e-3 and abs(state.position.y - y) < 1e-3:
                break
            time.sleep(0.05)
        else:
            raise RuntimeError("axes did not reach (%.0f, %.0f) mm" % (x * 1e3, y * 1e3))
    sub.unregister()
    say("%s: bus stepped x, y, z and the laser around a 150 mm square; %d answers from slave x" % (
        machine.name, len(responses)))


def follow_mtconnect(machine, args):
    """A machine reached only through its MTConnect agent: a whole cycle, its start and its end, as
    mtconnect_node reads them from the agent's stream (Execution ACTIVE, then READY)."""
    node = machine.nodes["mtconnect_node"].get("args", {})
    agent = "http://%s:%s" % (node.get("host", "127.0.0.1"), node.get("tcp_port", 5000))
    say("%s: waiting for a whole cycle read through its MTConnect agent %s" % (machine.name, agent))
    if not machine.cycle_ended.wait(args.timeout):
        raise RuntimeError("no whole cycle read through MTConnect within %.0f s" % args.timeout)
    with machine.lock:
        end = [e for e in machine.events if e.event == CycleEvent.CYCLE_END and math.isfinite(e.cycle_time)][0]
        starts = [e for e in machine.events if e.event == CycleEvent.CYCLE_START and e.header.stamp < end.header.stamp]
    # The agent reports the execution and the part counter as separate observations: the step of
    # the counter can come in the next chunk of the stream, after the cycle end.
    counted = (starts[-1].part_count + 1) if starts and starts[-1].part_count >= 0 else end.part_count
    deadline = time.time() + 3.0
    while True:
        with machine.lock:
            state = machine.states.get("mtconnect_node")
        if (state and state.part_count >= counted) or time.time() > deadline:
            break
        time.sleep(0.05)  # poll: the next state message
    parts = max(end.part_count, state.part_count if state else -1)
    say("%s: through MTConnect: cycle of %s ended after %.1f s, parts %d; now %s" % (
        machine.name, end.program, end.cycle_time, parts, describe(state)))


def shdr_values(line, items):
    """{(machine, item): value} of an SHDR line's `<machine>:<item>|value` pairs for these items."""
    tokens = line.split("|")
    found = {}
    for key, value in zip(tokens, tokens[1:]):
        machine, _, item = key.partition(":")
        if item in items:
            found[(machine, item)] = value
    return found


def report_mtconnect_out(cell, timeout=10.0):
    """Connects to the cell's SHDR adapter (mtconnect_adapter_node) as the shop's agent does and reads
    the full state it sends a new agent first, then the changes, until every machine it serves is
    AVAILABLE (a machine whose state the node has not received yet is UNAVAILABLE): every machine's
    availability and execution."""
    node = "/%s/mtconnect_adapter_node" % cell
    machines = rospy.get_param(node + "/machines")
    address, port = rospy.get_param(node + "/address", "127.0.0.1"), rospy.get_param(node + "/port")
    host = "127.0.0.1" if address == "0.0.0.0" else address
    deadline = time.time() + timeout
    while True:
        try:
            link = socket.create_connection((host, port), timeout=timeout)
            break
        except ConnectionRefusedError:
            if time.time() > deadline:
                raise RuntimeError("no SHDR adapter at %s:%d (mtconnect_adapter_node)" % (host, port))
            time.sleep(0.2)  # the node is still starting: try again
    seen, data = {}, b""

    def served():
        return ", ".join("%s %s %s" % (m, seen.get((m, "avail"), "?"), seen.get((m, "exec"), "?")) for m in machines)

    until = time.time() + timeout
    with link:
        while not all(seen.get((m, "avail")) == "AVAILABLE" and (m, "exec") in seen for m in machines):
            try:
                link.settimeout(max(0.01, until - time.time()))
                chunk = link.recv(4096)
            except socket.timeout:
                raise RuntimeError("not every machine AVAILABLE at the SHDR adapter %s:%d after %.0f s: %s" % (
                    host, port, timeout, served()))
            if not chunk:
                raise RuntimeError("the SHDR adapter at %s:%d closed the connection" % (host, port))
            *lines, data = (data + chunk).split(b"\n")
            for line in lines:
                seen.update(shdr_values(line.decode("utf-8", "replace"), ("avail", "exec")))
    say("mtconnect out: the cell's SHDR adapter at %s:%d serves %d machines to the shop's agent: %s" % (
        host, port, len(machines), served()))


# The demo's robot is a stand-in: before each of its steps at a machine it asks cell_monitor
# (docs/cell_monitor.md) whether it may enter, prints the answer with its reason, and gives a
# granted entry back at once (it does not reach in).
ROBOT = "demo_robot"
CELL_MONITOR = "/cell_monitor"


def ask_cell_monitor(machine, node):
    step = node.replace("_node", "")
    try:
        answer = rospy.ServiceProxy(CELL_MONITOR + "/request_entry", RequestEntry)(machine.name, ROBOT)
    except rospy.ServiceException as error:
        raise RuntimeError("cell_monitor did not answer before %s: %s" % (step, error))
    if answer.granted:
        say("%s: cell_monitor before %s: entry granted" % (machine.name, step))
        rospy.ServiceProxy(CELL_MONITOR + "/release_entry", RequestEntry)(machine.name, ROBOT)
    else:
        say("%s: cell_monitor before %s: refused: %s" % (machine.name, step, answer.reason))


STEPS = [("dnc_node", send_program), ("dprnt_node", probe_surface), ("ethernut_node", run_job),
         ("at_controller_node", follow_path), ("slave_bus_node", step_bus), ("mtconnect_node", follow_mtconnect)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell", required=True, help="cell description (YAML)")
    parser.add_argument("--output", required=True, help="folder for the surface map and the summary")
    parser.add_argument("--programs", required=True, help="the nodes' ~program_dir")
    parser.add_argument("--program", required=True, help="NC program sent by XModem")
    parser.add_argument("--drip-program", help="NC program drip-fed where dnc_node has enable_motion")
    parser.add_argument("--job", required=True, help="G-code job streamed to the ethernut")
    parser.add_argument("--path-program", required=True, help="G-code path for the '@' controller")
    parser.add_argument("--grid-points", type=int, default=100)
    parser.add_argument("--timeout", type=float, default=120.0)
    parser.add_argument("--once", action="store_true", help="exit after the scenario")
    parser.add_argument("--recorded", action="store_true",
                        help="a rosbag recorder runs: wait for it to subscribe before sending goals and commands")
    args = parser.parse_args(rospy.myargv()[1:])
    global RECORDERS, COUNTDOWNS
    RECORDERS = 1 if args.recorded else 0
    with open(args.cell) as f:
        description = yaml.safe_load(f)
    rospy.init_node("cell_demo", disable_signals=False)
    logging.getLogger("rosout").addFilter(UntrackedTransitionFilter())
    cell = description.get("cell", "cell")
    machines = [Machine(cell, entry) for entry in description.get("machines", [])]

    say("cell '%s': %d machines: %s" % (cell, len(machines), ", ".join(m.name for m in machines)))
    for machine in machines:
        if not machine.wait_up(60):
            say("%s: not up after 60 s: %s" % (machine.name, {n: describe(s) for n, s in machine.states.items()}))
            return 1
        for node, state in sorted(machine.states.items()):
            say("%s/%s: %s" % (machine.name, node, describe(state)))

    monitored = "cell_monitor" in description
    if monitored:
        try:
            rospy.wait_for_service(CELL_MONITOR + "/request_entry", 30)
        except rospy.ROSException:
            say("cell_monitor: no %s/request_entry after 30 s" % CELL_MONITOR)
            return 1
        # Its first answers are "no state received" until it has heard every machine's state.
        heard = threading.Event()
        sub = rospy.Subscriber("/cell_state", CellState,
                               lambda view: all(m.state_known for m in view.machines) and heard.set())
        if not heard.wait(30):
            say("cell_monitor: has not heard every machine's state after 30 s")
            return 1
        sub.unregister()
        if any("cycle_time" in entry for entry in description.get("machines", [])):
            COUNTDOWNS = Countdowns()

    failures = []
    if "mtconnect_adapter" in description:
        try:
            report_mtconnect_out(cell)
        except (OSError, RuntimeError, KeyError) as error:
            failures.append("mtconnect out: %s" % error)
            say("mtconnect out FAILED: %s" % error)
    threads = []
    for machine in machines:
        for node, step in STEPS:
            if node in machine.nodes:
                def run(machine=machine, step=step, node=node):
                    try:
                        if monitored:
                            ask_cell_monitor(machine, node)
                        step(machine, args)
                    except Exception as error:  # report every failure, keep the others running
                        failures.append("%s/%s: %s" % (machine.name, node, error))
                        say("%s/%s FAILED: %s" % (machine.name, node, error))
                threads.append(threading.Thread(target=run))
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()

    for machine in machines:
        if "haas_mdc_node" in machine.nodes or "mtconnect_node" in machine.nodes:
            ends = [e for e in machine.events if e.event == CycleEvent.CYCLE_END]
            via = " through MTConnect" if "mtconnect_node" in machine.nodes else ""
            say("%s: %d cycle events seen%s, %d cycle ends (a robot unloads on each)" % (
                machine.name, len(machine.events), via, len(ends)))
    say("scenario %s: %d steps, %d failed" % ("done" if not failures else "FAILED", len(threads), len(failures)))
    for failure in failures:
        say("  " + failure)
    if args.once or rospy.is_shutdown():
        return 1 if failures else 0
    say("the cell keeps running; Ctrl-C stops it")
    while not rospy.is_shutdown():
        rospy.sleep(10.0)
        for machine in machines:
            for node, state in sorted(machine.states.items()):
                say("%s/%s: %s" % (machine.name, node, describe(state)))
    return 1 if failures else 0


START = time.time()
if __name__ == "__main__":
    sys.exit(main())
