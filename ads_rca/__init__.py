"""ads_rca: root-cause analysis of autonomous-driving crashes, live on ROS 2 or offline."""

__version__ = "0.1.0"
