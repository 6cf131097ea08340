"""The live graph's pure core: per-module frame windows and the verdict aggregation.

No rclpy here. The monitor and aggregator nodes (``ads_rca.ros.monitor``,
``ads_rca.ros.aggregator``) are thin shells that feed these classes with converted messages
and publish what they return, so the scheduling and the semantics can be tested without DDS
and are guaranteed to be the engine's: every rule of the mode (oracles, analysed frames, ego,
window, look-ahead, attribution) is asked of the same
:class:`~ads_rca.oracles.semantics.Semantics` the engine asks.
"""
