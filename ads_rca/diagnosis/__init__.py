"""The diagnosis: the verdict types, the engine that judges a run, what the verdict may claim
(docs/verdicts.md), and how it is told (the summary, the mode comparison)."""
