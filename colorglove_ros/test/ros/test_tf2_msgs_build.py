"""tf2_msgs/TFMessage is importable on every install (scripts/setup.sh builds it into a pip-only
venv) and has the standard Jazzy definition, so /tf interoperates with tf2 and RViz."""
from __future__ import annotations

from rosbags.typesys import Stores, get_typestore


def test_tfmessage_matches_the_jazzy_definition() -> None:
    from tf2_msgs.msg import TFMessage

    ours = TFMessage.get_fields_and_field_types()
    _, reference = get_typestore(Stores.ROS2_JAZZY).fielddefs['tf2_msgs/msg/TFMessage']
    assert list(ours) == [name for name, _ in reference] == ['transforms']
    assert ours['transforms'] == 'sequence<geometry_msgs/TransformStamped>'
    (_, ((_, element), bound)) = reference[0][1]
    assert element == 'geometry_msgs/msg/TransformStamped' and bound == 0
