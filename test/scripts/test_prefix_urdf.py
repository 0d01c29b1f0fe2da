"""scripts/prefix_urdf.py: every name of the machine model prefixed, and the body-only model of a
machine whose nodes report no position (its moving joints and what they carry left out)."""
import os
import subprocess
import sys
import tempfile
import unittest
import xml.etree.ElementTree as ET

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SCRIPT = os.path.join(ROOT, "scripts", "prefix_urdf.py")
URDF = os.path.join(ROOT, "urdf", "mill_3axis.urdf")


def model(*args):
    out = subprocess.run([sys.executable, SCRIPT, URDF, *args], capture_output=True, text=True, check=True).stdout
    root = ET.fromstring(out)
    links = [link.get("name") for link in root.findall("link")]
    joints = {joint.get("name"): joint for joint in root.findall("joint")}
    return links, joints


class PrefixUrdf(unittest.TestCase):
    def test_every_link_and_joint_is_prefixed_and_the_axes_are_kept(self):
        links, joints = model("fanuc_mill/")
        self.assertTrue(links)
        self.assertTrue(all(name.startswith("fanuc_mill/") for name in links + list(joints)))
        moving = sorted(name for name, joint in joints.items() if joint.get("type") != "fixed")
        self.assertEqual(["fanuc_mill/x_axis", "fanuc_mill/y_axis", "fanuc_mill/z_axis"], moving)

    def test_the_body_only_model_has_no_moving_joint_and_nothing_they_carry(self):
        full_links, _ = model("m/")
        links, joints = model("m/", "--body-only")
        self.assertTrue(all(joint.get("type") == "fixed" for joint in joints.values()))
        self.assertEqual(["m/base", "m/column", "m/machine"], links)
        self.assertLess(len(links), len(full_links))
        for joint in joints.values():  # every joint left joins two links left
            self.assertIn(joint.find("parent").get("link"), links)
            self.assertIn(joint.find("child").get("link"), links)

    def test_the_body_only_model_keeps_machine_zero_where_the_axes_at_home_put_it(self):
        # With the axes at 0 the full model's machine zero is where the tool tip is: the head's
        # origin at home, z_axis's origin on the base. The body-only model fixes it there.
        _, full = model("m/")
        tool_at_home = [float(v) for v in full["m/z_axis"].find("origin").get("xyz").split()]
        _, joints = model("m/", "--body-only")
        home = joints["m/machine_at_home"]
        self.assertEqual("m/base", home.find("parent").get("link"))
        self.assertEqual("m/machine", home.find("child").get("link"))
        self.assertEqual(tool_at_home, [float(v) for v in home.find("origin").get("xyz").split()])

    def test_a_frame_behind_a_turned_joint_is_refused_not_misplaced(self):
        # A frame (tip) on an arm that the moving joint j also turns: translations alone would misplace it.
        urdf = ('<robot name="r"><link name="base"/><link name="arm"><visual><geometry><box size="1 1 1"/></geometry></visual></link><link name="tip"/>'
                '<joint name="j" type="revolute"><parent link="base"/><child link="arm"/>'
                '<origin xyz="0 0 1" rpy="0 0 1.57"/></joint>'
                '<joint name="f" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="1 0 0"/></joint></robot>')
        with tempfile.NamedTemporaryFile("w", suffix=".urdf") as f:
            f.write(urdf)
            f.flush()
            run = subprocess.run([sys.executable, SCRIPT, f.name, "--body-only"], capture_output=True, text=True)
        self.assertEqual(1, run.returncode)
        self.assertIn("cannot place tip", run.stderr)
        self.assertEqual("", run.stdout)

    def test_an_unknown_option_is_refused(self):
        run = subprocess.run([sys.executable, SCRIPT, URDF, "m/", "--bogus"], capture_output=True, text=True)
        self.assertEqual(2, run.returncode)
        self.assertIn("usage", run.stderr)


if __name__ == "__main__":
    unittest.main()
