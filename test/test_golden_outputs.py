"""``diagnose --json`` stays byte-identical on the example and every synthesised log.

The hashes in ``test/golden/diagnose_sha256.json`` were recorded on the commit before the
semantics redesign of issue #13 (see ``golden_outputs.py``); a change to any verdict, in
either mode, fails here and names the logs whose output changed.
"""

from __future__ import annotations

import json

from golden_outputs import STORED, cases, digests


def test_diagnose_json_is_byte_identical_to_the_recorded_outputs() -> None:
    stored = json.loads(STORED.read_text())
    assert len(stored) == 2 * (1 + len(cases()))
    now = digests()
    changed = sorted(k for k in stored if now.get(k) != stored[k])
    assert not changed, f"diagnose --json changed for: {', '.join(changed)}"
    assert now.keys() == stored.keys()
