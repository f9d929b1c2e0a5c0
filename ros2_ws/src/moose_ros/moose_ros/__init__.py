"""ROS 2 node graph of the moose-test collision avoidance (rclpy or Cyclone DDS)."""
