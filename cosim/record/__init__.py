"""Stage 5, recording: ROS 2 messages, one signal struct per component, and the MCAP writer."""
