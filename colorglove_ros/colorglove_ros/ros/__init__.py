"""ROS-facing modules: message conversions, image codec, bags, type store, launcher, node shells."""
