"""The robot log's topics, declared once: name, ROS 2 message type, and whether a live view latches it.

The recorder writes them with these types (cosim.record.recorder), a scenario's `[output.topics]`
may rename each of them (`odom = "/ground-truth-pose"`, ROS remapping), the live view sends the
latched ones' last message to a client that joins late (cosim.record.live), and docs/logs.md
describes them (a test checks that its table lists these and only these). `/signals/<component>`
is not here: its channels are made per component, with a schema generated from its ports.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Topic:
    name: str  # "/odom"
    ros_type: str  # "nav_msgs/msg/Odometry"
    latched: bool = False  # sent at t = 0 and when it changes: its last message holds until the next


TOPICS = (
    Topic("/odom", "nav_msgs/msg/Odometry"),
    Topic("/tf", "tf2_msgs/msg/TFMessage"),
    Topic("/pose", "geometry_msgs/msg/PoseStamped"),
    Topic("/scan", "sensor_msgs/msg/LaserScan"),
    Topic("/cmd_vel", "geometry_msgs/msg/Twist"),
    Topic("/plan", "nav_msgs/msg/Path", latched=True),
    Topic("/map", "nav_msgs/msg/OccupancyGrid", latched=True),
    Topic("/map_inflated", "nav_msgs/msg/OccupancyGrid", latched=True),
    Topic("/obstacles", "visualization_msgs/msg/MarkerArray", latched=True),
    Topic("/goal", "geometry_msgs/msg/PoseStamped", latched=True),
    Topic("/imu", "sensor_msgs/msg/Imu"),  # with [imu] (cosim.world.imu)
    # With [bumper]: false at t = 0, true when the footprint touches an obstacle (the outcome's collision).
    Topic("/bumper", "std_msgs/msg/Bool", latched=True),
)

TOPIC_TYPES = {topic.name: topic.ros_type for topic in TOPICS}
# `[output.topics]` keys: every topic above, without its slash.
REMAPPABLE_TOPICS = tuple(topic.name[1:] for topic in TOPICS)
LATCHED_TOPICS = frozenset(topic.name for topic in TOPICS if topic.latched)
