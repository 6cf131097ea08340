"""Recordings of real stacks: profiles that say which topic and type carry each model input,
the decoders of those types, and the coordinate conventions between ROS and the log's frame."""
