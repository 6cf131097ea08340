"""Subcommands of ``ads-rca``: each module has ``register(subparsers)`` setting ``run``.

The modules are named here, not imported: a run imports only its own command's module (a
``diagnose`` needs neither the bag writers of ``convert`` nor Dask of ``batch``), while
``ads-rca --help`` and an unknown command load them all.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: Command name -> its module, in the order ``ads-rca --help`` lists them.
COMMAND_MODULES: dict[str, str] = {
    "diagnose": "ads_rca.commands.diagnose_cmd",
    "batch": "ads_rca.commands.batch_cmd",
    "inspect": "ads_rca.commands.inspect_cmd",
    "demo": "ads_rca.commands.demo_cmd",
    "replay": "ads_rca.commands.replay_cmd",
    "synth": "ads_rca.commands.synth_cmd",
    "convert": "ads_rca.commands.convert_cmd",
    "watch": "ads_rca.commands.watch_cmd",
    "dashboard": "ads_rca.commands.dashboard_cmd",
}


def command_modules(only: str | None = None) -> list[ModuleType]:
    """The modules of every command, or of ``only`` (a command name) when it is one."""
    names = [only] if only in COMMAND_MODULES else list(COMMAND_MODULES)
    return [importlib.import_module(COMMAND_MODULES[name]) for name in names]
