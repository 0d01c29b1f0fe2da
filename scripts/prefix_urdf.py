#!/usr/bin/env python3
"""Prints a URDF with every link and joint name prefixed, for several machines in one tf tree.

robot_state_publisher no longer applies a tf_prefix, so each machine's robot_description is made
with its prefix baked in: `prefix_urdf.py urdf/mill_3axis.urdf haas_vf2/`.
"""
import sys
import xml.etree.ElementTree as ET


def prefixed(urdf_text, prefix):
    root = ET.fromstring(urdf_text)
    for element in root.iter():
        if element.tag in ("link", "joint") and "name" in element.attrib:
            element.set("name", prefix + element.get("name"))
        elif element.tag in ("parent", "child") and "link" in element.attrib:
            element.set("link", prefix + element.get("link"))
        elif element.tag == "mimic" and "joint" in element.attrib:
            element.set("joint", prefix + element.get("joint"))
    return ET.tostring(root, encoding="unicode")


def main(argv):
    if len(argv) < 2:
        sys.stderr.write("usage: prefix_urdf.py URDF [PREFIX]\n")
        return 2
    with open(argv[1]) as f:
        text = f.read()
    sys.stdout.write(prefixed(text, argv[2] if len(argv) > 2 else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
