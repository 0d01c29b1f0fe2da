"""The launch behaviour of a cell, checked with roslaunch's own loader (no master needed): every
node launch file takes params_file:= (loaded over its defaults, under the arguments given) and
respawn:=, no node is required, and scripts/cell_launch.py places the cell in its root frame,
passes each machine's profile to its nodes and writes an rviz configuration of the cell's own
machines."""
import glob
import os
import subprocess
import sys
import tempfile
import unittest
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# $(find cnc_bridge) in the launch files: this checkout, before any installed or built copy.
os.environ["ROS_PACKAGE_PATH"] = ROOT + ":/usr/share"
import roslaunch.config  # noqa: E402  (after ROS_PACKAGE_PATH, which rospkg reads)
import roslaunch.xmlloader  # noqa: E402

import yaml  # noqa: E402

LAUNCH = os.path.join(ROOT, "launch")
# Launch files that start one node of this package, named after it.
NODE_LAUNCH_FILES = sorted(
    path for path in glob.glob(os.path.join(LAUNCH, "*.launch"))
    if [node.get("type") for node in ET.parse(path).getroot().iter("node") if node.get("pkg") == "cnc_bridge"]
    == [os.path.basename(path)[:-len(".launch")]])


def load(path, *argv):
    """(params {name: value}, nodes) roslaunch would set and start for `path` with `argv`."""
    config = roslaunch.config.ROSLaunchConfig()
    roslaunch.xmlloader.XmlLoader().load(path, config, argv=list(argv), verbose=False)
    return {name: param.value for name, param in config.params.items()}, config.nodes


def parameter_file(test, values):
    """A YAML file of `values` that roslaunch reads by name; removed when `test` ends."""
    handle = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
    test.addCleanup(os.unlink, handle.name)
    yaml.safe_dump(values, handle)
    handle.close()
    return handle.name


class NodeLaunchFiles(unittest.TestCase):
    def test_the_node_launch_files_are_found(self):
        names = {os.path.basename(path) for path in NODE_LAUNCH_FILES}
        for expected in ("dnc_node.launch", "dprnt_node.launch", "haas_mdc_node.launch", "ethernut_node.launch",
                         "at_controller_node.launch", "slave_bus_node.launch", "surface_mapper.launch"):
            self.assertIn(expected, names)

    def test_no_node_is_required(self):
        for path in glob.glob(os.path.join(LAUNCH, "*.launch")):
            for node in ET.parse(path).getroot().iter("node"):
                self.assertNotEqual(node.get("required", "false").lower(), "true",
                                    "%s: node %s is required: its exit would stop the whole cell"
                                    % (os.path.basename(path), node.get("name")))

    def test_respawn_is_an_argument(self):
        for path in NODE_LAUNCH_FILES:
            with self.subTest(path=os.path.basename(path)):
                _, nodes = load(path)
                self.assertFalse(nodes[0].respawn)
                _, nodes = load(path, "respawn:=true", "respawn_delay:=5")
                self.assertTrue(nodes[0].respawn)
                self.assertEqual(nodes[0].respawn_delay, 5.0)

    def test_params_file_lies_between_defaults_and_arguments(self):
        for path in NODE_LAUNCH_FILES:
            with self.subTest(path=os.path.basename(path)):
                node = os.path.basename(path)[:-len(".launch")]
                defaults, _ = load(path)
                self.assertEqual(load(path, "params_file:=")[0], defaults, "an empty params_file changes nothing")
                self.assertEqual(load(path, "params_file:=none")[0], defaults, "params_file none changes nothing")
                # The first two parameters the launch file sets: one from the file, one from both.
                first, second = sorted(name for name in defaults if not isinstance(defaults[name], (dict, list)))[:2]
                ours = {"%s" % first.split("/")[-1]: self.other_than(defaults[first]),
                        "%s" % second.split("/")[-1]: self.other_than(defaults[second]), "profile_only": 42}
                with_file, _ = load(path, "params_file:=" + parameter_file(self, ours))
                self.assertEqual(with_file[first], ours[first.split("/")[-1]], "the file's value over the default")
                self.assertEqual(with_file["/%s/profile_only" % node], 42)
                argument = self.other_than(ours[second.split("/")[-1]])
                given, _ = load(path, "params_file:=" + parameter_file(self, ours), "%s:=%s" % (second.split("/")[-1],
                                                                                       argument))
                self.assertEqual(str(given[second]).lower(), str(argument).lower(), "the argument over the file")
                untouched = [name for name in defaults if name not in (first, second)]
                self.assertEqual({n: given[n] for n in untouched}, {n: defaults[n] for n in untouched})

    @staticmethod
    def other_than(value):
        if isinstance(value, bool):
            return not value
        if isinstance(value, (int, float)):
            return value + 3
        return str(value) + "_x"

    def test_dnc_node_takes_a_serial_profile_and_keeps_given_arguments(self):
        path = os.path.join(LAUNCH, "dnc_node.launch")
        profile = parameter_file(self, {"baud": 4800, "data_bits": 7, "parity": "even", "stop_bits": 2})
        params, _ = load(path, "params_file:=" + profile, "baud:=9600", "port:=/dev/ttyS3")
        self.assertEqual((params["/dnc_node/baud"], params["/dnc_node/data_bits"], params["/dnc_node/parity"],
                          params["/dnc_node/stop_bits"], params["/dnc_node/port"]), (9600, 7, "even", 2, "/dev/ttyS3"))
        self.assertEqual(params["/dnc_node/eob"], "lf", "a default the profile does not set stays")


# The control profiles of config/controls/ and the nodes each is written for.
PROFILE_NODES = {
    "haas_classic_rs232": ["dnc_node", "dprnt_node", "haas_mdc_node"],
    "haas_classic_rs232_7e1": ["dnc_node", "dprnt_node", "haas_mdc_node"],
    "haas_classic_device_server": ["dnc_node", "dprnt_node", "haas_mdc_node"],
    "haas_ngc_ethernet": ["haas_mdc_node", "dprnt_node"],
    "fanuc_0i_rs232": ["dnc_node"],
    "fanuc_0i_rs232_7n2": ["dnc_node"],
    "grbl_class_board": ["slave_bus_node"],
    "qcnc_ethernut": ["ethernut_node"],
    "at_controller": ["at_controller_node"],
}


def node_sources(node):
    """The C++ sources of a node and of the ROS helpers every node uses."""
    return glob.glob(os.path.join(ROOT, "src", "ros", "nodes", node.replace("_node", "") + "*.cpp")) + \
        glob.glob(os.path.join(ROOT, "src", "ros", "support", "*.cpp"))


class ControlProfiles(unittest.TestCase):
    def test_every_profile_is_known(self):
        found = sorted(os.path.basename(p)[:-len(".yaml")] for p in glob.glob(os.path.join(ROOT, "config", "controls",
                                                                                           "*.yaml")))
        self.assertEqual(found, sorted(PROFILE_NODES))

    def test_each_profile_loads_into_its_nodes(self):
        for profile, nodes in PROFILE_NODES.items():
            path = os.path.join(ROOT, "config", "controls", profile + ".yaml")
            with open(path) as f:
                values = yaml.safe_load(f)
            self.assertIsInstance(values, dict, path)
            sources = ""
            for source in {source for node in nodes for source in node_sources(node)}:
                with open(source) as f:
                    sources += f.read()
            for key in values:
                # A setting no node of the family reads is a typo or a dead line.
                self.assertIn('"%s"' % key, sources, "%s: no node of %s reads '%s'" % (profile, nodes, key))
            for node in nodes:
                with self.subTest(profile=profile, node=node):
                    params, _ = load(os.path.join(LAUNCH, node + ".launch"), "params_file:=" + path)
                    for key, value in values.items():
                        self.assertEqual(params["/%s/%s" % (node, key)], value)


class CellLaunch(unittest.TestCase):
    CELL = {
        "cell": "shop",
        "root_frame": "map",
        "simulate": False,
        "machines": [
            {"name": "lathe", "position": [0.0, 0.0, 0.0], "profile": "fanuc_0i_rs232",
             "nodes": [{"launch": "dnc_node", "args": {"port": "/dev/ttyUSB3"}}]},
            {"name": "router", "position": [3.0, 0.0, 0.0],
             "nodes": [{"launch": "ethernut_node", "args": {"host": "10.0.0.7"}}]},
        ],
    }

    def generate(self, description):
        with tempfile.TemporaryDirectory() as scratch:
            cell_yaml = os.path.join(scratch, "shop.yaml")
            with open(cell_yaml, "w") as f:
                yaml.safe_dump(description, f)
            rviz = os.path.join(scratch, "shop.rviz")
            launch = os.path.join(scratch, "shop.launch")
            subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "cell_launch.py"), cell_yaml, "-o", launch,
                            "--rviz", rviz], check=True)
            with open(rviz) as f:
                rviz_config = yaml.safe_load(f)
            params, nodes = load(launch, "gui:=true")
            return params, nodes, rviz_config, rviz

    def test_root_frame_profile_and_rviz_of_the_cell(self):
        params, nodes, rviz, rviz_path = self.generate(self.CELL)
        frame = [node for node in nodes if node.name == "cell_frame"][0]
        self.assertEqual(frame.args.split()[-2:], ["map", "shop"])
        self.assertEqual(rviz["Visualization Manager"]["Global Options"]["Fixed Frame"], "map")
        # The lathe's profile reaches its node; the arguments of the YAML win over it.
        self.assertEqual(params["/shop/lathe/dnc_node/port"], "/dev/ttyUSB3")
        self.assertEqual(params["/shop/lathe/dnc_node/stop_bits"], 2)
        self.assertEqual(params["/shop/router/ethernut_node/host"], "10.0.0.7")
        # rviz shows this cell's machines and what their nodes publish, opened by gui:=true.
        displays = {d["Name"]: d for d in rviz["Visualization Manager"]["Displays"]}
        self.assertEqual(displays["lathe"]["Robot Description"], "shop/lathe/robot_description")
        self.assertEqual(displays["router job path"]["Topic"], "/shop/router/job/path")
        self.assertEqual(displays["router tool path"]["Topic"], "/shop/router/tool_path")
        self.assertNotIn("haas_vf2", displays)
        viewer = [node for node in nodes if node.package == "rviz"][0]
        self.assertIn(rviz_path, viewer.args)

    def test_the_part_frame_of_a_surface_mapper_in_rviz(self):
        description = dict(self.CELL)
        description["machines"] = self.CELL["machines"] + [
            {"name": "mill", "position": [6.0, 0.0, 0.0], "tf_prefix": "vf2/",
             "nodes": [{"launch": "surface_mapper", "no_machine_args": True, "args": {"tf_prefix": "vf2/"}}]}]
        params, _, rviz, _ = self.generate(description)
        self.assertEqual(params["/shop/mill/surface_mapper/tf_prefix"], "vf2/")
        displays = {d["Name"]: d for d in rviz["Visualization Manager"]["Displays"]}
        self.assertEqual(displays["mill part frame"]["Class"], "rviz/Axes")
        self.assertEqual(displays["mill part frame"]["Reference Frame"], "vf2/part")
        self.assertEqual(displays["mill probe surface"]["Topic"], "/shop/mill/surface/cloud")
        self.assertNotIn("lathe part frame", displays)

    def test_a_program_origin_places_the_program_frame_and_shows_the_commanded_position(self):
        description = dict(self.CELL)
        lathe = dict(self.CELL["machines"][0], program_origin=[-0.1, 0, -0.3])
        description["machines"] = [lathe, self.CELL["machines"][1]]
        _, nodes, rviz, _ = self.generate(description)
        placement = [node for node in nodes if node.name == "program_placement"]
        self.assertEqual([node.namespace for node in placement], ["/shop/lathe/"])
        self.assertEqual(placement[0].args.split(), ["-0.1", "0", "-0.3", "0", "0", "0", "lathe/machine", "lathe/program"])
        displays = {d["Name"]: d for d in rviz["Visualization Manager"]["Displays"]}
        self.assertEqual(displays["lathe commanded position"]["Class"], "rviz/PointStamped")
        self.assertEqual(displays["lathe commanded position"]["Topic"], "/shop/lathe/dnc/commanded_position")
        # Without a program_origin the program's frame is nowhere in the cell: neither is shown.
        _, nodes, rviz, _ = self.generate(self.CELL)
        self.assertFalse([node for node in nodes if node.name == "program_placement"])
        self.assertNotIn("lathe commanded position", {d["Name"] for d in rviz["Visualization Manager"]["Displays"]})

    def test_a_program_origin_that_is_not_three_finite_numbers_is_refused(self):
        for origin in ([0.1, 0.2], [0.1, float("nan"), 0.0], [0.1, 1e400, 0.0], ["0.1", 0, 0], [True, 0, 0], "0 0 0"):
            with self.subTest(origin=origin), tempfile.TemporaryDirectory() as scratch:
                description = dict(self.CELL)
                description["machines"] = [dict(self.CELL["machines"][0], program_origin=origin)]
                cell_yaml = os.path.join(scratch, "shop.yaml")
                with open(cell_yaml, "w") as f:
                    yaml.safe_dump(description, f)
                launch = os.path.join(scratch, "shop.launch")
                run = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "cell_launch.py"), cell_yaml,
                                      "-o", launch], capture_output=True, text=True)
                self.assertEqual(1, run.returncode)
                self.assertIn("machine lathe: program_origin must be [x, y, z]", run.stderr)
                self.assertFalse(os.path.exists(launch))

    def test_root_frame_defaults_to_world(self):
        description = dict(self.CELL)
        del description["root_frame"]
        _, nodes, rviz, _ = self.generate(description)
        frame = [node for node in nodes if node.name == "cell_frame"][0]
        self.assertEqual(frame.args.split()[-2:], ["world", "shop"])
        self.assertEqual(rviz["Visualization Manager"]["Global Options"]["Fixed Frame"], "world")

    def test_mtconnect_adapter_serves_the_machines_without_an_agent_of_their_own(self):
        description = dict(self.CELL)
        description["machines"] = self.CELL["machines"] + [
            {"name": "mazak", "position": [6.0, 0.0, 0.0],
             "nodes": [{"launch": "mtconnect_node", "args": {"host": "10.0.0.9", "tcp_port": 5000}}]}]
        description["mtconnect_adapter"] = {"port": 7979, "agent_port": 5001}
        params, nodes, _, _ = self.generate(description)
        adapter = [node for node in nodes if node.type == "mtconnect_adapter_node"]
        self.assertEqual([node.namespace for node in adapter], ["/shop/"])
        # mazak is read through its own agent: served out again, the shop's agent would have it twice.
        self.assertEqual(params["/shop/mtconnect_adapter_node/machines"], ["lathe", "router"])
        self.assertEqual(params["/shop/mtconnect_adapter_node/port"], 7979)
        self.assertEqual(params["/shop/mtconnect_adapter_node/agent_port"], 5001)
        self.assertEqual(params["/shop/mazak/mtconnect_node/host"], "10.0.0.9")
        # Named in the YAML, the machines are those.
        description["mtconnect_adapter"] = {"machines": ["router"]}
        params, _, _, _ = self.generate(description)
        self.assertEqual(params["/shop/mtconnect_adapter_node/machines"], ["router"])
        # Without the section, no adapter.
        _, nodes, _, _ = self.generate(self.CELL)
        self.assertFalse([node for node in nodes if node.type == "mtconnect_adapter_node"])


if __name__ == "__main__":
    unittest.main()


class RostestLaunchFiles(unittest.TestCase):
    """Every rostest's launch file loads: an argument given twice to an include, an unknown
    argument or a missing file would otherwise only show as a test that never ran."""

    def test_every_rostest_file_loads(self):
        files = sorted(glob.glob(os.path.join(ROOT, "test", "rostest", "*.test")))
        self.assertGreater(len(files), 10)
        for path in files:
            with self.subTest(path=os.path.basename(path)):
                load(path)
