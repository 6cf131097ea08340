"""The diagnosis: the verdict types, the engine that judges a run, what the verdict may claim
(docs/verdicts.md), how it is told (the summary, the mode comparison), and the protocol of a
run's own figures beside it (``scoring.py``)."""
