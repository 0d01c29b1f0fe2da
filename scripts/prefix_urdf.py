#!/usr/bin/env python3
"""Prints a URDF with every link and joint name prefixed, for several machines in one tf tree.

robot_state_publisher no longer applies a tf_prefix, so each machine's robot_description is made
with its prefix baked in: `prefix_urdf.py urdf/mill_3axis.urdf haas_vf2/`.

`--body-only` leaves out every moving joint and what it carries: the model of a machine whose nodes
report no position (a drip-fed control) shows its body, not axes placed where nothing says they are.
The frames among what the axes carry (links without geometry, such as `machine`, machine zero) stay,
fixed where they are with every axis at 0 (home), so that frames placed relative to them (a
program's zero, `<tf_prefix>program`) have a place in the tree.
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
    """The URDF without its moving joints and every link and joint downstream of them, but for the
    frames among those links, each fixed to the nearest link left at its pose with the axes at 0."""
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
    frames = [link for link in root.findall("link")
              if link.get("name") in dropped_links and link.find("visual") is None and link.find("collision") is None]
    homes = [home_joint(frame.get("name"), joints, dropped_links) for frame in frames]
    for joint in joints:
        if joint.find("child").get("link") in dropped_links:
            root.remove(joint)
    for link in root.findall("link"):
        if link.get("name") in dropped_links and link not in frames:
            root.remove(link)
    for joint in homes:
        root.append(joint)
    return ET.tostring(root, encoding="unicode")


def home_joint(frame, joints, dropped_links):
    """A fixed joint placing \p frame on the nearest link not dropped, at its pose with every joint
    between them at 0: the sum of their origins (a rotated origin on the way is refused)."""
    into = {joint.find("child").get("link"): joint for joint in joints}
    offset = [0.0, 0.0, 0.0]
    link = frame
    while link in dropped_links:
        joint = into[link]
        origin = joint.find("origin")
        if origin is not None:
            if any(float(v) != 0.0 for v in origin.get("rpy", "0 0 0").split()):
                raise ValueError("--body-only cannot place %s at home: joint %s turns its frame (rpy)"
                                 % (frame, joint.get("name")))
            offset = [a + float(b) for a, b in zip(offset, origin.get("xyz", "0 0 0").split())]
        link = joint.find("parent").get("link")
    home = ET.Element("joint", name=frame + "_at_home", type="fixed")
    ET.SubElement(home, "parent", link=link)
    ET.SubElement(home, "child", link=frame)
    ET.SubElement(home, "origin", xyz=" ".join("%g" % round(v, 9) for v in offset))
    return home


def main(argv):
    flags = [a for a in argv[1:] if a.startswith("--")]
    args = [a for a in argv[1:] if not a.startswith("--")]
    if not args or any(flag != "--body-only" for flag in flags):
        sys.stderr.write("usage: prefix_urdf.py URDF [PREFIX] [--body-only]\n")
        return 2
    with open(args[0]) as f:
        text = f.read()
    if flags:
        try:
            text = body_only(text)
        except ValueError as e:
            sys.stderr.write("prefix_urdf.py: %s\n" % e)
            return 1
    sys.stdout.write(prefixed(text, args[1] if len(args) > 1 else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
