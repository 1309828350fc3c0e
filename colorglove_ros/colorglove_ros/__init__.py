"""Colour-glove articulated hand tracking (Wang and Popovic 2009) as ROS 2 Jazzy nodes."""
