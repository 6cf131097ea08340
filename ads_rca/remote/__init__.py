"""Results on Eclipse Zenoh for remote dashboards: the pure core.

Key naming, the endpoint configuration, per-key rate limits and the bounded history a late
dashboard queries are plain Python with no zenoh or rclpy import, so the bridge node, the
terminal and the web dashboards share one reading of them.
"""
