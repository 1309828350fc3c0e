"""The tracking algorithm as plain Python modules: no rclpy import anywhere below here."""
