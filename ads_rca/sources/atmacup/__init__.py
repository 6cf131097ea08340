"""An atmaCup #18 table: independent ego snapshots, and a submission's predicted ego paths
scored as the competition did."""
