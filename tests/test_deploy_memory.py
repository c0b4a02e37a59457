"""A deployment's memory does not grow with the messages it receives:
`deploy` may run for a day (LONGEST_DEPLOYMENT), and the run pumps the
LCM on which it waited for the robot, whose handlers stay subscribed
(pydrake's Subscribe offers no unsubscribe)."""

import gc
import threading
import time
import tracemalloc

import numpy as np
from pydrake.lcm import DrakeLcm

from drake_wbc.deployment.deploy import wait_for_next, wait_for_status
from drake_wbc.hardware import messages
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.robot.model import HOME_ARM_POSITIONS

MESSAGES = 10_000
"""Messages on each status channel after the start: 100 s of the robot's
100 Hz streams."""


def statuses(channels, utime):
    """(channel, bytes) of the robot's four statuses, stamped `utime`."""
    return [
        (channels.base_state, messages.encode_base_state(utime, np.zeros(6))),
        (channels.arm_status, messages.encode_arm_status(
            utime, HOME_ARM_POSITIONS, np.zeros(6))),
        (channels.wrist_wrench, messages.encode_wrench(utime, np.zeros(6))),
        (channels.obstacle_points,
         messages.encode_obstacle_points(utime, np.zeros((0, 2))))]


def python_heap():
    """Bytes of Python's heap traced since tracemalloc started, garbage
    collected."""
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


def test_the_start_keeps_nothing_of_the_messages_after_it():
    """What deploy does before the controller starts, on LCM in memory:
    it waits for every status (wait_for_status), then for the next base
    state (wait_for_next), here sent by a robot every millisecond. The
    handler of the second kept an entry for every base state after it,
    for the whole run (over UDP the process grew by 0.8 kB a second;
    here 10,000 base states took 85 kB). Now 10,000 messages on each
    status channel leave Python's heap as it was, within 1 kB."""
    options = HardwareOptions(lcm_url="memq://")
    channels = options.channels
    lcm = DrakeLcm("memq://")
    waiting = threading.Event()

    def robot():
        # In real time: the waits are on the wall clock.
        utime = 0
        while not waiting.is_set():
            utime += 1000
            for channel, data in statuses(channels, utime):
                lcm.Publish(channel, data)
            time.sleep(0.001)

    sender = threading.Thread(target=robot)
    sender.start()
    try:
        assert wait_for_status(lcm, options, HOME_ARM_POSITIONS.size,
                               timeout=5.0) is not None
        assert wait_for_next(lcm, channels.base_state, timeout=5.0)
    finally:
        waiting.set()
        sender.join()
    lcm.HandleSubscriptions(0)
    after = statuses(channels, 10**9)
    tracemalloc.start()
    try:
        before = python_heap()
        for _ in range(MESSAGES // 100):
            for _ in range(100):
                for channel, data in after:
                    lcm.Publish(channel, data)
            lcm.HandleSubscriptions(0)
        growth = python_heap() - before
    finally:
        tracemalloc.stop()
    print(f"Python's heap grew by {growth} bytes")
    assert growth < 1000
