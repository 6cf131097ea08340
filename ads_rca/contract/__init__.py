"""The message contract without ROS: what travels on which topic, and how (no rclpy import here).

Topic table, model ↔ message conversion, the fast CDR encoder and decoder, the playback
timeline, the assembler and the message definitions live here so that ``sources/``, ``live/`` and
the nodes in ``ros/`` share one copy. No module here imports rclpy or a message package at
import time: message classes are imported inside the functions that build them
(test/test_import_layers.py pins it).
"""
