"""The live graph's pure core: per-module frame windows and the verdict aggregation.

No rclpy here. The monitor and aggregator nodes (``ads_rca.ros.monitor``,
``ads_rca.ros.aggregator``) are thin shells that feed these classes with converted messages
and publish what they return, so the scheduling and the semantics can be tested without DDS
and are guaranteed to be the engine's: every frame is judged by the same oracle functions
(``ads_rca.engine.oracles_for``) and the verdict by the same ``ads_rca.engine.attribute``.
"""
