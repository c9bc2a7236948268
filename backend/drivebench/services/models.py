"""Tables of the DriveBench database. The schema changes only through migrations (``drivebench/migrations``)."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, DateTime, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from drivebench.services.database import Base


def utcnow() -> datetime:
    return datetime.now(UTC)


class PlannedNetworkRow(Base):
    """A saved network plan; ``body`` is the plan as JSON (``services.planner.NetworkPlan``)."""

    __tablename__ = "planned_network"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(200), nullable=False, index=True)
    created: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow)
    updated: Mapped[datetime] = mapped_column(DateTime(timezone=True), nullable=False, default=utcnow,
                                              onupdate=utcnow)
    body: Mapped[dict[str, Any]] = mapped_column(JSON, nullable=False)
