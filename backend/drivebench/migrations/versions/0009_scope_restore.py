"""A scope recording sampled by PDO writes what it will change on the nodes before it changes anything (issue 31):
the restore record a server start uses when a recording was killed mid-way

Revision ID: 0009_scope_restore
Revises: 0008_share_link_shows
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009_scope_restore"
down_revision = "0008_share_link_shows"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "scope_restore",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("bus", sa.String(200), nullable=False),
        sa.Column("server", sa.String(120), nullable=False),
        sa.Column("body", sa.JSON(), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("scope_restore")
