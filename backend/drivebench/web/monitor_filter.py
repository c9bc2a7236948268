"""The monitor's filter as a client sends it (``PUT /api/sessions/{id}/monitor/filter`` and the monitor
websocket's ``filter`` message)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, Field, model_validator

from drivebench.i18n import _

ServiceName = Literal["NMT", "SYNC", "EMCY", "TIME", "PDO", "SDO", "Heartbeat", "LSS", "Unknown", "Error frame"]


class FilterBody(BaseModel):
    """What the counter tables and the trace show; counting and bus load always take every frame."""

    nodes: list[Annotated[int, Field(ge=1, le=127)]] = Field(default_factory=list, description="empty = all")
    services: list[ServiceName] = Field(default_factory=list, description="empty = all")
    cob_min: int = Field(0, ge=0, le=0x1FFFFFFF)
    cob_max: int = Field(0x1FFFFFFF, ge=0, le=0x1FFFFFFF)

    @model_validator(mode="after")
    def _ordered(self) -> FilterBody:
        if self.cob_min > self.cob_max:
            raise ValueError(_("cob_min must not be above cob_max"))
        return self
