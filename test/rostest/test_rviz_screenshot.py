#!/usr/bin/env python3
"""What a person sees: a screenshot of rviz on the demo cell must show the machines, not an empty grid.

The scene area of the rviz window is analysed: the machine model draws lit grey castings, a dark
table and a blue saddle, so a rendered machine gives many pixels far from the background colour
and a patch of saturated blue per machine whose axes are known; an empty grid gives neither
(measured: an empty grid draws about 4 % of the scene and no blue; the four-machine cell about
9.5 % and 0.05 % blue with one machine's joints known, 0.16 % with all four).
"""
import os
import subprocess
import sys
import time
import unittest

import numpy as np
import rospy
from PIL import Image

from cnc_bridge.msg import MachineState

BACKGROUND = np.array([48, 48, 48])


def screenshot(path):
    xwd = subprocess.run(["xwd", "-root", "-silent"], capture_output=True, check=True).stdout
    subprocess.run(["convert", "xwd:-", path], input=xwd, check=True)
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def scene_statistics(image):
    """Fractions of the scene area (rviz's 3D view: the region with the background colour
    around it) that differ from the background, and that are saturated blue."""
    background = np.all(np.abs(image - BACKGROUND) <= 3, axis=2)
    rows = np.where(background.mean(axis=1) > 0.05)[0]
    cols = np.where(background.mean(axis=0) > 0.05)[0]
    if len(rows) == 0 or len(cols) == 0:
        return 0.0, 0.0, 0
    scene = image[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    distance = np.abs(scene - BACKGROUND).sum(axis=2)
    r, g, b = scene[..., 0], scene[..., 1], scene[..., 2]
    blue = (b > r + 50) & (b > 100)
    return float((distance > 60).mean()), float(blue.mean()), scene.shape[0] * scene.shape[1]


class RvizScreenshot(unittest.TestCase):
    def test_scene_shows_the_machine(self):
        topic = rospy.get_param("~state_topic")
        path = rospy.get_param("~screenshot")
        rospy.wait_for_message(topic, MachineState, timeout=30)
        deadline = time.time() + 60
        filled = blue = 0.0
        area = 0
        while time.time() < deadline:
            filled, blue, area = scene_statistics(screenshot(path))
            if filled > 0.07 and blue > 0.0003:
                break
            time.sleep(1.0)  # rviz is still loading the model: look again
        rospy.loginfo("scene %d px: %.1f%% drawn, %.2f%% blue; screenshot %s", area, 100 * filled, 100 * blue, path)
        self.assertGreater(area, 200 * 200, "no rviz scene area found on the screen")
        self.assertGreater(filled, 0.07, "the scene is (nearly) empty: %.1f%% drawn" % (100 * filled))
        self.assertGreater(blue, 0.0003, "too few machine models (blue saddles) in the scene: %.2f%% blue" % (100 * blue))


if __name__ == "__main__":
    import rostest
    rospy.init_node("test_rviz_screenshot")
    rostest.rosrun("cnc_bridge", "rviz_screenshot", RvizScreenshot, sys.argv)
