"""colorglove_msgs/GestureEvent: its gesture-name constants are the core's, and the adapters
round-trip a core event (no rclpy.init)."""
from __future__ import annotations

import pytest
from builtin_interfaces.msg import Time
from colorglove_msgs.msg import GestureEvent as GestureEventMsg
from std_msgs.msg import Header

from colorglove_ros.core.hand.gestures import GESTURE_NAMES, GestureError, GestureEvent
from colorglove_ros.ros.conversions import gesture_event_from_msg, gesture_event_to_msg


def test_message_constants_are_the_gesture_names() -> None:
    constants = {getattr(GestureEventMsg, name) for name in dir(GestureEventMsg)
                 if name.isupper() and isinstance(getattr(GestureEventMsg, name), str)}
    assert constants == set(GESTURE_NAMES)
    assert (GestureEventMsg.START, GestureEventMsg.END) == (0, 1)


@pytest.mark.parametrize('state, code', [('start', GestureEventMsg.START),
                                         ('end', GestureEventMsg.END)])
def test_round_trip(state: str, code: int) -> None:
    event = GestureEvent('pinch_ring', state, 0.8125, 12.5)
    header = Header(stamp=Time(sec=12, nanosec=500_000_000), frame_id='left_palm')
    msg = gesture_event_to_msg(event, header, 'left')
    assert (msg.hand, msg.gesture, msg.event, msg.header.frame_id) == (
        'left', 'pinch_ring', code, 'left_palm')
    assert gesture_event_from_msg(msg) == event
    msg.event = 7
    with pytest.raises(GestureError):
        gesture_event_from_msg(msg)
