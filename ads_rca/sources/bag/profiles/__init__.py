"""Recordings of real stacks: profiles that say which topic and type carry each model input,
the decoders of those types, and the coordinate conventions between ROS and the log's frame."""

#: The profile of this project's own topics (the contract, docs/topics.md): the default.
DEFAULT_PROFILE = "ads_rca"
#: The profiles shipped with the package (``ads_rca/sources/bag/profiles/builtin/<name>.yaml``).
BUILTIN_PROFILES = ("ads_rca", "carla-autoware", "vision_msgs", "autoware")
