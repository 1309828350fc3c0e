"""gesture_node: gesture events (pinches, grab, point, open hand) from ``hand/joint_states``,
each as a ``colorglove_msgs/GestureEvent`` on ``hand/gestures`` and, as before, as a
``std_msgs/String`` line ``name:state:confidence`` on ``hand/gesture_events`` (e.g.
``pinch_index:start:0.93``); ``no hand`` lines on ``hand/tracking_status`` for ``lose_after_s``
(default the core's) end the active ones, a shorter loss (a few refused frames) decides
nothing.
The evidence of each frame's own ``tracking:`` status line (``core.hand.frame_evidence``,
paired by the frame's stamp) gates it (``evidence_min_constraints``, default the core's;
``evidence_max_reprojection_px``, default off; 0 turns either off): a frame of weak evidence
decides nothing. A classifier's scores are bounded by the pose's geometry as the core's
default ``GestureConfig().shape`` sets (``core.hand.gestures.ShapeGate``). With an
``image_classifier_file`` (``colorglove_train_hand_classifiers --what
gesture_images``; default the core's, none) it also subscribes to ``hand/observation``
(segmentation_node's ``colorglove_msgs/HandObservation``) and gives each pose the observation
of its own stamp, combined with the pose classifier (``image_weight``); a pose whose
observation has not come is scored from the pose alone."""
from __future__ import annotations

import math
import sys

import numpy as np
from builtin_interfaces.msg import Time
from colorglove_msgs.msg import GestureEvent as GestureEventMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String

from colorglove_ros.core.hand.frame_evidence import (
    EvidenceGate,
    EvidencePairer,
    FrameEvidence,
    parse_tracking_status,
)
from colorglove_ros.core.hand.frames import finger_joint_names, hand_root_frame
from colorglove_ros.core.hand.gestures import (
    DEFAULT_GESTURE_CLASSIFIER,
    DEFAULT_GESTURE_IMAGE_CLASSIFIER,
    GESTURE_FEATURES,
    GestureConfig,
    GestureDetector,
    GestureEvent,
    format_event,
)
from colorglove_ros.core.hand.poses import full_pose
from colorglove_ros.ros.conversions import (
    gesture_event_to_msg,
    pose_from_joint_state_msg,
    stamp_key,
    stamp_to_seconds,
)
from colorglove_ros.ros.nodes.common import (
    JOINT_STATES_TOPIC,
    TRACKING_STATUS_TOPIC,
    ObservationFeatures,
    StartupError,
    declare,
    declare_classifier,
    declare_frame_prefix,
    declare_image_classifier,
    hand_model_from_calibration,
    run_node,
    startup_errors,
)
from colorglove_ros.ros.pose_pairing import is_no_hand_status

__all__ = ['GestureNode', 'main', 'HANDS']

HANDS = ('right', 'left')


class GestureNode(Node):
    """Runs the gesture detector on every JointState."""

    def __init__(self, **kwargs) -> None:
        super().__init__('gestures', **kwargs)
        self.model = hand_model_from_calibration(self, 'gesture_node')
        frame_prefix = declare_frame_prefix(self, 'gesture_node')
        self.joint_names = finger_joint_names(frame_prefix)
        self.hand = declare(self, 'hand', HANDS[0],
                            "which hand the events are of, 'right' or 'left' (GestureEvent.hand)")
        if self.hand not in HANDS:
            raise StartupError(f'gesture_node cannot start: hand must be one of {HANDS}, '
                               f'got {self.hand!r}')
        self.hand_frame = hand_root_frame(frame_prefix)
        self.publish_text = declare(self, 'publish_text_events', True,
                                    'also publish each event as a text line on '
                                    'hand/gesture_events (std_msgs/String)')
        classifier = declare_classifier(self, 'gesture_node', DEFAULT_GESTURE_CLASSIFIER,
                                        GESTURE_FEATURES, 'rules on the finger geometry')
        min_constraints = declare(self, 'evidence_min_constraints',
                                  GestureConfig().evidence.min_constraints,
                                  'skip frames whose newest tracking status matched fewer '
                                  'constraints than this (0: off)', 0.0, 1000.0)
        max_reprojection = declare(self, 'evidence_max_reprojection_px', 0.0,
                                   'skip frames whose newest tracking status has a larger '
                                   'reprojection error, px (0: off)', 0.0, 1000.0)
        lose_after_s = declare(self, 'lose_after_s', GestureConfig().lose_after_s,
                               'seconds of no-hand status lines before the active gestures '
                               'end (0: at the first)', 0.0, 60.0)
        image, image_weight = declare_image_classifier(
            self, 'gesture_node', DEFAULT_GESTURE_IMAGE_CLASSIFIER,
            'colorglove_train_hand_classifiers --what gesture_images',
            GestureConfig().image_weight)
        gate = EvidenceGate(max_reprojection or math.inf, min_constraints)
        with startup_errors('gesture_node'):
            self.detector = GestureDetector(
                self.model, GestureConfig(evidence=gate, image_weight=image_weight,
                                          lose_after_s=lose_after_s),
                classifier, image)
        self.observations = ObservationFeatures(self) if image is not None else None
        # each JointState (with its observation's features) waits for its frame's status line
        self.pairer: EvidencePairer[tuple[np.ndarray, Time, np.ndarray | None]] = \
            EvidencePairer()
        self.event_pub = self.create_publisher(GestureEventMsg, 'hand/gestures', 10)
        self.text_pub = self.create_publisher(String, 'hand/gesture_events', 10) \
            if self.publish_text else None
        self.create_subscription(JointState, JOINT_STATES_TOPIC, self.on_joints, 10)
        self.create_subscription(String, TRACKING_STATUS_TOPIC, self.on_status, 10)

    def _publish(self, events: list[GestureEvent], header: Header) -> None:
        for event in events:
            self.event_pub.publish(gesture_event_to_msg(event, header, self.hand))
            if self.text_pub is not None:
                self.text_pub.publish(String(data=format_event(event)))

    def on_joints(self, msg: JointState) -> None:
        """Detect on one frame's finger joints (the wrist pose does not matter), once its
        status line is in."""
        try:
            q = full_pose(self.model, pose_from_joint_state_msg(msg, self.joint_names))
        except (KeyError, ValueError) as exc:
            self.get_logger().warn(f'bad JointState: {exc}', throttle_duration_sec=1.0)
            return
        stamp = msg.header.stamp
        observation = None if self.observations is None else self.observations.pop(stamp)
        self._detect(self.pairer.add_frame(stamp_key(stamp), (q, stamp, observation)))

    def _detect(self, frames: list[tuple[tuple[np.ndarray, Time, np.ndarray | None],
                                         FrameEvidence | None]]) -> None:
        for (q, stamp, observation), evidence in frames:
            try:
                events = self.detector.update(q, stamp_to_seconds(stamp), evidence, observation)
            except ValueError as exc:
                self.get_logger().warn(f'bad JointState: {exc}', throttle_duration_sec=1.0)
                continue
            self._publish(events, Header(stamp=stamp, frame_id=self.hand_frame))

    def on_status(self, msg: String) -> None:
        """Pair the tracker's evidence with its frame; end the active gestures when it loses
        the hand."""
        self._detect(self.pairer.add_status(parse_tracking_status(msg.data)))
        if is_no_hand_status(msg.data):      # its line (no stamp) released the waiting frame
            now = self.get_clock().now()
            self._publish(self.detector.update(None, now.nanoseconds * 1e-9),
                          Header(stamp=now.to_msg(), frame_id=self.hand_frame))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``gesture_node``."""
    return run_node(GestureNode, args)


if __name__ == '__main__':
    sys.exit(main())
