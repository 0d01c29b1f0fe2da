#!/usr/bin/env python3
"""The hostile-input suite (test/rostest/hostile_input.test): every service of every node called and
every goal sent with adversarial values, table-driven from the services the nodes advertise.

For each call: an answer (or a failed call) within CALL_BOUND seconds, the node alive afterwards,
nothing outside the program folder changed, and, for a call that was not carried out (a failed
answer, a goal that did not succeed), nothing new on the simulator's side. A number no wire carries
exactly (NaN, +/-inf, 1e300) and a file name no file system takes (64 KB, not UTF-8) are never
accepted. After a node's rows, a valid request to it succeeds. The rows a node accepted are printed
at the end."""
import hashlib
import math
import os
import stat
import sys
import threading
import time
import unittest

import actionlib
import rosnode
import rospy
import rosservice
import rostest
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Point, PoseStamped
from roslib.message import get_service_class

import cnc_bridge.msg as cnc

CALL_BOUND = 20.0  # s: every call answered within this
FIFO_GRACE = 4.0  # s: a call still waiting then is let go by opening the FIFO it may be blocked on


class Raw(str):
    """A string field sent as these raw bytes (genpy encodes a str field with .encode())."""

    def __new__(cls, data):
        obj = super().__new__(cls, data.decode("latin-1"))
        obj.raw = data
        return obj

    def encode(self, *args, **kwargs):
        return self.raw


def hostile_strings(sandbox):
    return [("empty", ""), ("64 KB", "x" * 65536), ("..", ".."), ("a path up", "../outside/secret.nc"),
            ("an absolute path outside", os.path.join(sandbox, "outside", "secret.nc")),
            ("a directory", "somedir"), ("a symlink out of the folder", "link_out.nc"), ("a FIFO", "fifo.nc"),
            ("bytes not UTF-8", Raw(b"\xff\xfe\x80O1.nc"))]


FLOATS = [("NaN", math.nan), ("+inf", math.inf), ("-inf", -math.inf), ("1e300", 1e300), ("-1", -1.0)]
INT_LIMITS = {"int8": (-128, 127), "int16": (-2 ** 15, 2 ** 15 - 1), "int32": (-2 ** 31, 2 ** 31 - 1),
              "int64": (-2 ** 63, 2 ** 63 - 1), "uint8": (0, 255), "uint16": (0, 2 ** 16 - 1),
              "uint32": (0, 2 ** 32 - 1), "uint64": (0, 2 ** 64 - 1)}


def hostile_values(slot_type, sandbox):
    if slot_type == "string":
        return hostile_strings(sandbox)
    if slot_type in ("float32", "float64"):
        return FLOATS
    if slot_type in INT_LIMITS:
        low, high = INT_LIMITS[slot_type]
        return [("-1", -1)] * (low < 0) + [("max", high)] + [("min", low)] * (low < 0)
    return []


def snapshot_tree(root):
    """Every file under root (not following links): path -> (mode, size, sha256)."""
    out = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = os.path.join(folder, name)
            info = os.lstat(path)
            digest = ""
            if stat.S_ISREG(info.st_mode):
                with open(path, "rb") as f:
                    digest = hashlib.sha256(f.read()).hexdigest()
            out[path] = (info.st_mode, info.st_size, digest)
    return out


class LogPeer:
    """A simulator that logs what it receives, one line each, while the node also polls it: a
    refused call must add no line of a kind the log did not hold before the call."""

    def __init__(self, path):
        self.path = path

    def snapshot(self):
        try:
            with open(self.path, "rb") as f:
                data = f.read()
        except FileNotFoundError:
            data = b""
        return len(data), set(data.splitlines())

    def news(self, before):
        offset, seen = before
        with open(self.path, "rb") as f:
            f.seek(offset)
            new = f.read().splitlines()
        return [line for line in new if line not in seen]


class FolderPeer:
    """A peer whose side is a folder (the control's store, the share)."""

    def __init__(self, path):
        self.path = path

    def snapshot(self):
        return snapshot_tree(self.path)

    def news(self, before):
        now = self.snapshot()
        return sorted(p for p in set(now) | set(before) if now.get(p) != before.get(p))


class GoalOutcome:
    """A goal's end as a service answer reads: state, success (or granted), message (or reason)."""

    def __init__(self, state, result):
        self.state = state
        self.result = result
        self.success = bool(result is not None and getattr(result, "success", getattr(result, "granted", False)))
        self.message = (getattr(result, "message", "") or getattr(result, "reason", "")) if result is not None else ""


def call_bounded(fn, fifo_path):
    """Runs fn() in a thread; returns (answered, value or exception, fifo_released)."""
    box = {}

    def run():
        try:
            box["value"] = fn()
        except Exception as e:  # a failed call is an answer too
            box["value"] = e

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(FIFO_GRACE)
    released = False
    end = time.monotonic() + CALL_BOUND - FIFO_GRACE
    while thread.is_alive() and time.monotonic() < end:
        # A node blocked opening the FIFO (perhaps more than once) is let go each time.
        released = release_fifo(fifo_path) or released
        thread.join(0.2)
    return not thread.is_alive(), box.get("value"), released


def release_fifo(path):
    """Lets go a reader blocked opening or reading the FIFO: open its write end and close it."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError:
        return False
    os.close(fd)
    return True


def answer_text(value):
    if isinstance(value, Exception):
        return "call failed: %s" % value
    return getattr(value, "message", "") or ""


def failed(value):
    """The call was not carried out: a failed call, an answer with success false, a goal that did
    not succeed."""
    if isinstance(value, Exception):
        return True
    if isinstance(value, GoalOutcome):
        return value.state != GoalStatus.SUCCEEDED or not value.success
    return getattr(value, "success", True) is False


# Values no wire carries exactly ("exact or refused", docs/SAFETY.md): a row with one of these in a number
# field must not succeed.
NOT_REPRESENTABLE = ("NaN", "+inf", "-inf", "1e300")
# Names no file system takes: a row with one of these as a file name must not succeed.
NOT_A_FILE_NAME = ("64 KB", "bytes not UTF-8")


class HostileInput(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_hostile_input")
        cls.ns = rospy.get_param("~namespace")
        cls.sandbox = rospy.get_param("~sandbox")
        cls.programs = os.path.join(cls.sandbox, "programs")
        with open(rospy.get_param("~program"), "rb") as f:
            cls.program = f.read()
        logs = os.path.join(cls.sandbox, "logs")
        cls.nodes = {
            "dnc_node": FolderPeer(os.path.join(cls.sandbox, "control")),
            "share_node": FolderPeer(os.path.join(cls.sandbox, "share")),
            "ethernut_node": LogPeer(os.path.join(logs, "ethernut_messages.txt")),
            "at_controller_node": LogPeer(os.path.join(logs, "at_commands.txt")),
            "haas_mdc_node": LogPeer(os.path.join(logs, "mdc_queries.txt")),
            "dprnt_node": None,  # only listens: nothing goes to its peer
            "slave_bus_node": LogPeer(os.path.join(logs, "slave_deliveries.txt")),
            "cell_monitor": None,  # no wire: it only reads the machines' states
            "surface_mapper": None,  # no wire unless its work-offset write is on (it is off here)
        }
        for node in cls.nodes:
            rospy.wait_for_service("%s/%s/get_loggers" % (cls.ns, node), timeout=60)
        cls.accepted = []  # rows a node answered with success: listed at the end
        cls.fifo_blocked = []  # rows answered only once the FIFO was opened by the test

    @classmethod
    def tearDownClass(cls):
        print("\nhostile rows answered with success (to be refused by whole-request validation):")
        for row in cls.accepted:
            print("  " + row)
        print("rows that waited on the FIFO until the test opened it:")
        for row in cls.fifo_blocked:
            print("  " + row)

    # --- fixtures ---------------------------------------------------------------------------------

    def plant(self):
        """The hostile files in the program folder, made again before each row (a receive may
        replace them) and the folder outside with a file that must never change."""
        outside = os.path.join(self.sandbox, "outside")
        os.makedirs(outside, exist_ok=True)
        with open(os.path.join(outside, "secret.nc"), "w") as f:
            f.write("%\nO01111 (OUTSIDE THE PROGRAM FOLDER)\nM30\n%\n")
        os.makedirs(os.path.join(self.programs, "somedir"), exist_ok=True)
        link = os.path.join(self.programs, "link_out.nc")
        if not os.path.islink(link):
            if os.path.lexists(link):
                os.unlink(link)
            os.symlink(os.path.join(outside, "secret.nc"), link)
        fifo = os.path.join(self.programs, "fifo.nc")
        if os.path.lexists(fifo) and not stat.S_ISFIFO(os.lstat(fifo).st_mode):
            os.unlink(fifo)
        if not os.path.lexists(fifo):
            os.mkfifo(fifo)
        with open(os.path.join(self.programs, "O05555.nc"), "wb") as f:
            f.write(self.program)
        with open(os.path.join(self.programs, "square.nc"), "w") as f:
            f.write("G21 G90\nG1 X1 Y1 F600\nG1 X0 Y0\nM30\n")

    def outside(self):
        return snapshot_tree(os.path.join(self.sandbox, "outside"))

    # --- one row ----------------------------------------------------------------------------------

    def check_row(self, node, row, fn):
        self.plant()
        peer = self.nodes[node]
        before_peer = peer.snapshot() if peer else None
        before_outside = self.outside()
        started = time.monotonic()
        answered, value, released = call_bounded(fn, os.path.join(self.programs, "fifo.nc"))
        took = time.monotonic() - started
        self.assertTrue(answered, "%s: no answer within %.0f s" % (row, CALL_BOUND))
        if released:
            self.fifo_blocked.append(row)
        ping = rosnode.rosnode_ping("%s/%s" % (self.ns, node), max_count=1, verbose=False)
        self.assertTrue(ping, "%s: %s is not alive after the call (%s)" % (row, node, answer_text(value)))
        self.assertEqual(self.outside(), before_outside, "%s: a file outside the program folder changed" % row)
        # A call that was not carried out puts nothing on the wire, whatever its answer says.
        if peer and failed(value):
            self.assertEqual(peer.news(before_peer), [], "%s: failed (%s) but the peer received something"
                             % (row, answer_text(value)[:200]))
        label = row.rsplit("=", 1)[-1].split(" (")[0]
        if label in NOT_REPRESENTABLE or (label in NOT_A_FILE_NAME and ("file" in row or "name" in row)):
            self.assertTrue(failed(value), "%s: accepted (%s): a value the wire cannot carry exactly must be "
                            "refused" % (row, answer_text(value)[:200]))
        if not isinstance(value, Exception) and getattr(value, "success", False):
            self.accepted.append("%s (%.1f s): %s" % (row, took, answer_text(value)[:160]))
        return value

    # --- services ---------------------------------------------------------------------------------

    def services_of(self, node):
        name = "%s/%s" % (self.ns, node)
        skip = ("get_loggers", "set_logger_level")
        services = []
        for service in sorted(rosservice.get_service_list(node=name)):
            base = service.rsplit("/", 1)[1]
            # The runtime switches (set_motion_enabled, set_kill_enabled) only take a bool; they stay as set.
            if base in skip or base.endswith("_enabled"):
                continue
            services.append((service, get_service_class(rosservice.get_service_type(service))))
        return services

    # The other fields of a row's request, so that the hostile value reaches the node's checks of
    # it (a variable that may be written, an axis that exists, a tool).
    BASE = {"write_variable": {"variable": 100}, "jog": {"axis": "x"}, "tool_change": {"tool": 1}}

    def hostile_service_rows(self, node):
        for service, cls in self.services_of(node):
            proxy = rospy.ServiceProxy(service, cls)
            request_class = cls._request_class
            base = self.BASE.get(service.rsplit("/", 1)[1], {})
            rows = 0
            for slot, slot_type in zip(request_class.__slots__, request_class._slot_types):
                for label, value in hostile_values(slot_type, self.sandbox):
                    request = request_class(**base)
                    setattr(request, slot, value)
                    self.check_row(node, "%s %s=%s" % (service, slot, label), lambda: proxy(request))
                    rows += 1
            if rows == 0:  # a service without fields (std_srvs/Trigger): called once
                self.check_row(node, "%s ()" % service, lambda: proxy(request_class()))

    # --- goals ------------------------------------------------------------------------------------

    def send_goal(self, client, goal):
        client.send_goal(goal)
        if not client.wait_for_result(rospy.Duration(CALL_BOUND - 1)):
            client.cancel_goal()
            client.wait_for_result(rospy.Duration(2))
            raise AssertionError("no result")
        return GoalOutcome(client.get_state(), client.get_result())

    def goal_rows(self, node, action, action_class, base, fields):
        client = actionlib.SimpleActionClient("%s/%s/%s" % (self.ns, node, action), action_class)
        self.assertTrue(client.wait_for_server(rospy.Duration(30)), "%s/%s: no action server" % (node, action))
        goal_class = type(action_class().action_goal.goal)
        for field, slot_type in fields:
            for label, value in hostile_values(slot_type, self.sandbox):
                goal = goal_class(**base)
                setattr(goal, field, value)
                self.check_row(node, "%s/%s goal %s=%s (%s)" % (node, action, field, label, base),
                               lambda: self.send_goal(client, goal))
        return client, goal_class

    # --- usable afterwards ------------------------------------------------------------------------

    def assert_transfer_works(self, node, peer_file):
        service = "%s/%s/send_program" % (self.ns, node)
        send = rospy.ServiceProxy(service, get_service_class("cnc_bridge/SendProgram"))
        self.plant()
        answer = send(file="O05555.nc", protocol="")
        self.assertTrue(answer.success, "%s: a valid send after the hostile rows: %s" % (node, answer.message))
        with open(peer_file, "rb") as f:
            self.assertEqual(f.read().replace(b"\r", b""), self.program.replace(b"\r", b""))
        os.unlink(peer_file)

    # --- the tests --------------------------------------------------------------------------------

    def test_a_directory_named_as_the_program_fails_and_frees_the_node(self):
        """A directory named as the program: its read once threw past the transfer; through the service
        the transfer slot, the port and the port lock stayed held, through the action the node died.
        Now the call fails naming the file, the node lives, and a valid transfer runs at once."""
        for node, peer_file in (("dnc_node", os.path.join(self.sandbox, "control", "O05555.nc")),
                                ("share_node", os.path.join(self.sandbox, "share", "O05555.nc"))):
            self.plant()
            peer = self.nodes[node]
            before = peer.snapshot()
            send = rospy.ServiceProxy("%s/%s/send_program" % (self.ns, node), get_service_class("cnc_bridge/SendProgram"))
            answer = send(file="somedir", protocol="")
            self.assertFalse(answer.success, "%s: %s" % (node, answer.message))
            self.assertIn("somedir", answer.message)
            client = actionlib.SimpleActionClient("%s/%s/transfer" % (self.ns, node), cnc.TransferAction)
            self.assertTrue(client.wait_for_server(rospy.Duration(30)))
            result = self.send_goal(client, cnc.TransferGoal(direction="send", file="somedir"))
            self.assertEqual(result.state, GoalStatus.ABORTED, "%s: %s" % (node, result.message))
            self.assertIn("somedir", result.message)
            self.assertTrue(rosnode.rosnode_ping("%s/%s" % (self.ns, node), max_count=1, verbose=False))
            self.assertEqual(peer.news(before), [], "%s: the peer received something for the refused calls" % node)
            # The slot, the port and the lock were released: the next transfers run at once.
            self.assert_transfer_works(node, peer_file)
            result = self.send_goal(client, cnc.TransferGoal(direction="send", file="O05555.nc"))
            self.assertEqual(result.state, GoalStatus.SUCCEEDED, "%s: %s" % (node, result.message))
            os.unlink(peer_file)

    def test_dnc_node(self):
        self.hostile_service_rows("dnc_node")
        for direction in ("send", "receive"):
            self.goal_rows("dnc_node", "transfer", cnc.TransferAction, {"direction": direction},
                           [("file", "string"), ("protocol", "string"), ("start_line", "uint32"),
                            ("start_block", "string")])
        self.goal_rows("dnc_node", "transfer", cnc.TransferAction, {"file": "O05555.nc"}, [("direction", "string")])
        self.assert_transfer_works("dnc_node", os.path.join(self.sandbox, "control", "O05555.nc"))

    def test_share_node(self):
        self.hostile_service_rows("share_node")
        for direction in ("send", "receive"):
            self.goal_rows("share_node", "transfer", cnc.TransferAction, {"direction": direction},
                           [("file", "string"), ("protocol", "string")])
        self.assert_transfer_works("share_node", os.path.join(self.sandbox, "share", "O05555.nc"))

    def test_ethernut_node(self):
        self.hostile_service_rows("ethernut_node")
        client, goal_class = self.goal_rows("ethernut_node", "run_job", cnc.RunJobAction, {}, [("file", "string")])
        point = [Point(0.001, 0.002, 0.0)]
        for label, value in FLOATS:
            for axis in ("x", "y", "z"):
                bad = Point(0.001, 0.002, 0.0)
                setattr(bad, axis, value)
                goal = goal_class(points=point + [bad])
                self.check_row("ethernut_node", "run_job point %s=%s" % (axis, label),
                               lambda: self.send_goal(client, goal))
        for label, value in hostile_strings(self.sandbox):
            goal = goal_class(points=point)
            goal.header.frame_id = value
            self.check_row("ethernut_node", "run_job frame_id=%s" % label, lambda: self.send_goal(client, goal))
        self.plant()
        result = self.send_goal(client, goal_class(points=point))
        self.assertEqual(result.state, GoalStatus.SUCCEEDED, "a valid job afterwards: %s" % result.message)

    def test_at_controller_node(self):
        self.hostile_service_rows("at_controller_node")
        base = {"gcode_file": "square.nc", "tool": -1}
        client, goal_class = self.goal_rows(
            "at_controller_node", "follow_path", cnc.AtFollowPathAction, base,
            [("gcode_file", "string"), ("feed_rate", "float64"), ("spindle_speed", "float64"), ("tool", "int32"),
             ("coolant", "int8")])
        self.goal_rows("at_controller_node", "follow_path", cnc.AtFollowPathAction,
                       {"gcode_file": "square.nc", "tool": 1}, [("tool_length", "float64")])
        for label, value in FLOATS[:4]:  # -1 m is a valid position (soft limits will refuse it)
            goal = goal_class(tool=-1)
            pose = PoseStamped()
            pose.pose.orientation.w = 1.0
            pose.pose.position.x = value
            goal.path.poses = [PoseStamped(), pose]
            goal.path.poses[0].pose.orientation.w = 1.0
            self.check_row("at_controller_node", "follow_path pose x=%s" % label,
                           lambda: self.send_goal(client, goal))
        self.plant()
        result = self.send_goal(client, goal_class(**base))
        self.assertEqual(result.state, GoalStatus.SUCCEEDED, "a valid path afterwards: %s" % result.message)

    def test_haas_mdc_node(self):
        self.hostile_service_rows("haas_mdc_node")
        read = rospy.ServiceProxy("%s/haas_mdc_node/read_variable" % self.ns,
                                  get_service_class("cnc_bridge/MdcReadVariable"))
        answer = read(variable=100)
        self.assertTrue(answer.success, "a valid read afterwards: %s" % answer.message)

    def test_dprnt_node(self):
        self.hostile_service_rows("dprnt_node")
        clear = rospy.ServiceProxy("%s/dprnt_node/clear" % self.ns, get_service_class("std_srvs/Trigger"))
        answer = clear()
        self.assertTrue(answer.success, "a valid clear afterwards: %s" % answer.message)

    def test_slave_bus_node(self):
        self.hostile_service_rows("slave_bus_node")  # its only services are switches: none hostile
        switch = rospy.ServiceProxy("%s/slave_bus_node/set_motion_enabled" % self.ns, get_service_class("std_srvs/SetBool"))
        self.assertTrue(switch(data=False).success)

    def test_cell_monitor(self):
        self.hostile_service_rows("cell_monitor")
        client, goal_class = self.goal_rows(
            "cell_monitor", "hold_entry", cnc.HoldEntryAction, {"machine": "haas_ngc", "robot": "r1", "timeout": 0.5},
            [("machine", "string"), ("robot", "string")])
        # A timeout that is no number must be refused at once (inf, 1e300 and 0 or less mean "until
        # cancelled", which the row's bound would only time out).
        goal = goal_class(machine="haas_ngc", robot="r1", timeout=float("nan"))
        outcome = self.check_row("cell_monitor", "hold_entry goal timeout=nan", lambda: self.send_goal(client, goal))
        self.assertIsInstance(outcome, GoalOutcome, "a NaN timeout: %s" % answer_text(outcome))
        self.assertEqual(outcome.state, GoalStatus.REJECTED, "a NaN timeout: %s" % outcome.message)
        self.assertIn("not a number", outcome.message)
        request = rospy.ServiceProxy("%s/cell_monitor/request_entry" % self.ns, get_service_class("cnc_bridge/RequestEntry"))
        answer = request(machine="haas_ngc", robot="r1")  # its machine reports nothing here: never safe
        self.assertFalse(answer.granted)
        self.assertTrue(answer.reason, "a valid request afterwards is answered with its reason")

    def test_surface_mapper(self):
        before = set(os.listdir(self.sandbox))
        self.hostile_service_rows("surface_mapper")
        maps = os.path.join(self.sandbox, "maps")
        stray = sorted(set(os.listdir(self.sandbox)) - before - {"maps"})
        self.assertEqual(stray, [], "files written beside the map folder: %s" % stray)
        clear = rospy.ServiceProxy("%s/surface_mapper/clear" % self.ns, get_service_class("std_srvs/Trigger"))
        self.assertTrue(clear().success, "a valid clear afterwards")
        if os.path.isdir(maps):
            for name in os.listdir(maps):
                self.assertRegex(name, r"^[A-Za-z0-9_.-]+$", "a map file named from a hostile value: %r" % name)


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_hostile_input", HostileInput, sys.argv)
