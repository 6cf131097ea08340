"""The message contract without ROS: what travels on which topic (no rclpy import here).

The pure half of the topic contract lives here so that ``io/`` and ``live/`` can name topics
without importing ``ros/``; ``ads_rca.ros.topics`` adds the message types and QoS.
"""
