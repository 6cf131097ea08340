"""Where runs come from: one folder per source (an ADS running log, rosbag2 bags and their
profiles, each driving dataset we read), each declaring its ``Source`` (``formats.py``), and
the registry that tells them apart, reads them and lists the scorers of their data
(``registry.py``)."""
