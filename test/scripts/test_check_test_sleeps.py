"""A sleep in test/ says why it is not a wait for an event, or the lint fails."""
import unittest

import check_test_sleeps


class CheckTestSleeps(unittest.TestCase):
    def problems(self, text, path="test/rostest/x.cpp"):
        return check_test_sleeps.problems_in(path, text)

    def test_a_bare_sleep_is_a_problem_naming_its_line(self):
        found = self.problems("int a;\nros::Duration(0.5).sleep();\n")
        self.assertEqual(len(found), 1)
        self.assertEqual(found[0][0], "test/rostest/x.cpp:2")

    def test_a_sleep_with_its_reason_on_the_line_or_just_above_passes(self):
        self.assertEqual(self.problems("std::this_thread::sleep_for(20ms);  // poll: a file\n"), [])
        self.assertEqual(self.problems("// A measurement window, closed by a marker.\n"
                                       "ros::WallDuration(0.5).sleep();\n"), [])
        self.assertEqual(self.problems("time.sleep(0.1)  # the stall under test\n", "test/x.py"), [])

    def test_a_reason_far_above_or_in_code_does_not_count(self):
        text = "// poll\nint a;\nint b;\nusleep(10);\n"
        self.assertEqual(len(self.problems(text)), 1)

    def test_python_and_shell_sleeps_are_found(self):
        self.assertEqual(len(self.problems("time.sleep(1)\n", "test/x.py")), 1)
        self.assertEqual(len(self.problems("rospy.sleep(1)\n", "test/x.py")), 1)
        self.assertEqual(len(self.problems("  sleep 2\n", "test/x.sh")), 1)
        self.assertEqual(len(self.problems("a; sleep 0.1; b\n", "test/x.sh")), 1)

    def test_the_repository_has_none(self):
        found, checked = check_test_sleeps.problems()
        self.assertGreater(checked, 50)
        self.assertEqual(found, [])


if __name__ == "__main__":
    unittest.main()
