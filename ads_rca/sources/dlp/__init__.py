"""A Dragon Lake Parking scene: one agent taken as the ego."""
