"""Where runs come from: one folder per source (an ADS running log, rosbag2 bags and their
profiles, a CARLA experiment-client run, a DLP scene, an OpenLane-V2 segment, an atmaCup
#18 table) and the registry that tells them apart and reads them (`registry.py`)."""
