"""ROS 2 nodes: message and parameter translation around the core (the only modules importing rclpy)."""
