"""A CARLA experiment-client run folder: telemetry, plan, events as annotations, and the
client's own safety and comfort figures."""
