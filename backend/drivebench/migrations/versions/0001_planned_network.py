"""planned_network: saved network plans (name, timestamps, the plan as JSON)

Revision ID: 0001_planned_network
Revises:
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001_planned_network"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "planned_network",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated", sa.DateTime(timezone=True), nullable=False),
        sa.Column("body", sa.JSON(), nullable=False),
    )
    op.create_index("ix_planned_network_name", "planned_network", ["name"])


def downgrade() -> None:
    op.drop_index("ix_planned_network_name", table_name="planned_network")
    op.drop_table("planned_network")
