"""Keeps every message of a topic for a rostest, and waits for the one a test expects."""
import threading
import time

import rospy


class Collector:
    """Subscribes and keeps messages; wait(predicate) returns the first that satisfies it."""

    def __init__(self, topic, msg_type, queue_size=10000):
        self.cv = threading.Condition()
        self.messages = []
        self.sub = rospy.Subscriber(topic, msg_type, self.on_message, queue_size=queue_size)

    def on_message(self, msg):
        with self.cv:
            self.messages.append(msg)
            self.cv.notify_all()

    def count(self):
        with self.cv:
            return len(self.messages)

    def wait_connected(self, timeout=20.0):
        """A message published before the subscription is connected is lost: wait for the publisher."""
        deadline = time.monotonic() + timeout
        while self.sub.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)  # polling the connection count: rospy offers no wait for it
        return self.sub.get_num_connections() > 0

    def wait(self, predicate, timeout=30.0, start=0):
        """The first message from index start on that satisfies predicate, or None after timeout s."""
        found = []

        def ready():
            found[:] = [m for m in self.messages[start:] if predicate(m)][:1]
            return bool(found)

        with self.cv:
            return found[0] if self.cv.wait_for(ready, timeout) else None
