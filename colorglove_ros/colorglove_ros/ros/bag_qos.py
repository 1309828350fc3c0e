"""QoS for recording and replaying bags the way rosbag2 Jazzy does (``rosbag2_transport``'s
``qos.cpp``): the recorder asks for what every publisher offers, the player offers again what
the recorded publishers offered."""
from __future__ import annotations

from collections.abc import Sequence

from rclpy.duration import Duration
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSLivelinessPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
)
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability

from colorglove_ros.ros.bags import INFINITE_QOS_TIME

__all__ = ['RECORD_DEPTH', 'PLAY_DEPTH', 'subscription_qos_for_offers', 'qos_from_recorded',
           'publisher_qos_for_recorded']

RECORD_DEPTH = 100
PLAY_DEPTH = 10


def subscription_qos_for_offers(offered: Sequence[QoSProfile]) -> QoSProfile:
    """The recorder's request for a topic: reliable (transient local) only when every publisher
    offers reliable (transient local), else best effort (volatile), so that it matches every
    publisher and loses nothing a reliable publisher sends. No publisher known: reliable."""
    reliable = all(p.reliability == QoSReliabilityPolicy.RELIABLE for p in offered)
    latched = bool(offered) and all(
        p.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=QoSHistoryPolicy.KEEP_LAST, depth=RECORD_DEPTH,
        reliability=QoSReliabilityPolicy.RELIABLE if reliable else QoSReliabilityPolicy.BEST_EFFORT,
        durability=(QoSDurabilityPolicy.TRANSIENT_LOCAL if latched
                    else QoSDurabilityPolicy.VOLATILE))


def _duration(value) -> Duration:
    return Duration(seconds=int(value.sec), nanoseconds=int(value.nsec))


def qos_from_recorded(recorded: Qos) -> QoSProfile:
    """An rclpy profile from one offered profile stored in rosbag2 metadata (history ``unknown``
    in metadata becomes keep-last with the player's depth)."""
    history = QoSHistoryPolicy.KEEP_ALL if recorded.history == QosHistory.KEEP_ALL \
        else QoSHistoryPolicy.KEEP_LAST
    reliability = {QosReliability.RELIABLE: QoSReliabilityPolicy.RELIABLE,
                   QosReliability.BEST_EFFORT: QoSReliabilityPolicy.BEST_EFFORT}.get(
        recorded.reliability, QoSReliabilityPolicy.RELIABLE)
    durability = {QosDurability.TRANSIENT_LOCAL: QoSDurabilityPolicy.TRANSIENT_LOCAL,
                  QosDurability.VOLATILE: QoSDurabilityPolicy.VOLATILE}.get(
        recorded.durability, QoSDurabilityPolicy.VOLATILE)
    liveliness = {QosLiveliness.MANUAL_BY_TOPIC: QoSLivelinessPolicy.MANUAL_BY_TOPIC}.get(
        recorded.liveliness, QoSLivelinessPolicy.AUTOMATIC)
    profile = QoSProfile(history=history, depth=max(int(recorded.depth), PLAY_DEPTH),
                         reliability=reliability, durability=durability, liveliness=liveliness)
    for name in ('deadline', 'lifespan', 'liveliness_lease_duration'):
        value = getattr(recorded, name)
        default = (value.sec, value.nsec) in ((0, 0), (INFINITE_QOS_TIME.sec,
                                                       INFINITE_QOS_TIME.nsec))
        if not default:
            setattr(profile, name, _duration(value))
    return profile


def publisher_qos_for_recorded(recorded: Sequence[Qos]) -> QoSProfile:
    """The player's offer for a topic: the recorded publishers' profile when they all agree on
    reliability and durability (``ros2 bag play`` does the same), else reliable volatile."""
    profiles = [qos_from_recorded(q) for q in recorded]
    if profiles and all(p.reliability == profiles[0].reliability
                        and p.durability == profiles[0].durability for p in profiles):
        return profiles[0]
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=PLAY_DEPTH,
                      reliability=QoSReliabilityPolicy.RELIABLE,
                      durability=QoSDurabilityPolicy.VOLATILE)
