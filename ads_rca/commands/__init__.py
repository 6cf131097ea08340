"""Subcommands of ``ads-rca``: each module has ``register(subparsers)`` setting ``run``."""

from __future__ import annotations

from types import ModuleType

from ads_rca.commands import (
    batch_cmd,
    convert_cmd,
    dashboard_cmd,
    demo_cmd,
    diagnose_cmd,
    inspect_cmd,
    replay_cmd,
    synth_cmd,
    watch_cmd,
)

#: In the order ``ads-rca --help`` lists them.
COMMANDS: tuple[ModuleType, ...] = (
    diagnose_cmd,
    batch_cmd,
    inspect_cmd,
    demo_cmd,
    replay_cmd,
    synth_cmd,
    convert_cmd,
    watch_cmd,
    dashboard_cmd,
)
