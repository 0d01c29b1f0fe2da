#!/usr/bin/env python3
"""Prints a URDF with every link and joint name prefixed, for several machines in one tf tree.

robot_state_publisher no longer applies a tf_prefix, so each machine's robot_description is made
with its prefix baked in: `prefix_urdf.py urdf/mill_3axis.urdf haas_vf2/`.

`--body-only` leaves out every moving joint and what it carries: the model of a machine whose nodes
report no position (a drip-fed control) shows its body, not axes placed where nothing says they are.
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


def body_only(urdf_text):
    """The URDF without its moving joints and every link and joint downstream of them."""
    root = ET.fromstring(urdf_text)
    joints = [j for j in root.findall("joint")]
    dropped_links = set()
    changed = True
    while changed:
        changed = False
        for joint in joints:
            child = joint.find("child").get("link")
            moving = joint.get("type") != "fixed"
            if child not in dropped_links and (moving or joint.find("parent").get("link") in dropped_links):
                dropped_links.add(child)
                changed = True
    for joint in joints:
        if joint.find("child").get("link") in dropped_links:
            root.remove(joint)
    for link in root.findall("link"):
        if link.get("name") in dropped_links:
            root.remove(link)
    return ET.tostring(root, encoding="unicode")


def main(argv):
    flags = [a for a in argv[1:] if a.startswith("--")]
    args = [a for a in argv[1:] if not a.startswith("--")]
    if not args or any(flag != "--body-only" for flag in flags):
        sys.stderr.write("usage: prefix_urdf.py URDF [PREFIX] [--body-only]\n")
        return 2
    with open(args[0]) as f:
        text = f.read()
    if flags:
        text = body_only(text)
    sys.stdout.write(prefixed(text, args[1] if len(args) > 1 else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
