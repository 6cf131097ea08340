"""An OpenLane-V2 segment: traffic elements and lane graphs, and the benchmark's own figures
for a map-perception model."""
