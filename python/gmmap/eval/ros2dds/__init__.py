"""A stand-in ROS 2 graph on real DDS (the `cyclonedds` package) and the zenoh-plugin-ros2dds
bridge host (``make ros2``), for testing ``gmmap robot --ros2`` against software gmmap did not
write. Robots never import this package."""
