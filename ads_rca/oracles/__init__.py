"""The four module oracles (perception, prediction, planning, control) in both semantics."""
