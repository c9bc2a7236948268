"""The ``commands`` section of a device profile: how the device saves its parameters and loads its defaults.

Each command is one write: ``ref`` := ``value`` (a number, or four letters a CiA 301 signature stands for:
``"save"``, ``"load"``). Without the section a device is treated by CiA 301: save 0x1010.1 := "save", restore
defaults 0x1011.1 := "load" (taking effect at the next reset node). Reset node is always the NMT command.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivebench.device.profiles.templates import check_template
from drivebench.i18n import N_


class CommandWrite(BaseModel):
    """One device command as a write, and what the tool tells the user once it went through."""

    model_config = ConfigDict(extra="forbid")

    ref: str = Field(min_length=1)
    """The parameter or object written (``C00002/11``, ``0x1010.1``)."""
    value: int | str
    """The value written: a number, or a four-letter signature (``"save"``: its ASCII bytes, little-endian)."""
    done: str = Field(min_length=1)
    """What the result says; ``{node}`` stands for the node id (``Node {node} saved all parameter sets.``)."""
    after_reset: bool = False
    """Takes effect only at the next reset node (CiA 301 restore defaults)."""

    @model_validator(mode="after")
    def _check_done(self) -> CommandWrite:
        check_template(self.done, {"node": 1}, "done")
        return self

    @property
    def raw(self) -> int:
        if isinstance(self.value, int):
            return self.value
        return int.from_bytes(self.value.encode("ascii"), "little")

    @property
    def via(self) -> str:
        """What was sent, as the result shows it: ``C00002/11 = 1``, ``0x1010.1 = 'save'``."""
        return f"{self.ref} = {self.value!r}"


CIA301_SAVE = CommandWrite(ref="0x1010.1", value="save", done=N_("Node {node} saved its parameters."))
CIA301_RESTORE = CommandWrite(ref="0x1011.1", value="load", after_reset=True,
                              done=N_("Node {node} restores its defaults at the next reset node."))


class CommandsSection(BaseModel):
    """The device's own save / load-defaults writes where they are not CiA 301's 0x1010/0x1011."""

    model_config = ConfigDict(extra="forbid")

    save: CommandWrite | None = None
    restore_defaults: CommandWrite | None = None
    """Restore (load) the default setting."""
