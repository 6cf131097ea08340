"""How to read a bag: the options every command and the player share.

``profile`` names which topics and types carry the model's inputs (a built-in profile or a
YAML file, docs/recordings.md); ``remap`` renames a bag's topics onto the contract's (profile
``ads_rca`` only: a profile names its topics itself, so the pair is refused here, once for
every caller); ``msg_path`` gives directories of ``.msg`` files for message types a bag
carries no definition of. The CLI flags are
``--profile``, ``--remap`` and ``--msg-path``; the player's ROS parameters ``profile``,
``bag_remap`` and ``msg_path``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ads_rca.errors import InputError
from ads_rca.sources.bag.profiles import DEFAULT_PROFILE


@dataclass(frozen=True)
class BagOptions:
    """See the module docstring."""

    profile: str = DEFAULT_PROFILE
    remap: str | None = None
    msg_path: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.remap is not None and not self.contract:
            raise InputError(
                f"--remap applies to the {DEFAULT_PROFILE} profile; profile "
                f"{self.profile!r} names its topics itself (copy it and edit the topics)"
            )

    @property
    def contract(self) -> bool:
        """The bag carries this project's own topics (read by the contract's reader)."""
        return self.profile == DEFAULT_PROFILE
