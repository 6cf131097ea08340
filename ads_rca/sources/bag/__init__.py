"""rosbag2 bags (MCAP and sqlite3): our own topics, and real stacks' recordings read through
profiles (``profiles/``); the message types from the bag itself."""
