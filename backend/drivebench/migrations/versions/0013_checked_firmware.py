"""checked_firmware: firmware files checked against a node and waiting to be sent (issue 32, program download), so a
download or the wizard's program step finds its file after a server restart and on a second server

Revision ID: 0013_checked_firmware
Revises: 0012_line_wizard
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0013_checked_firmware"
down_revision = "0012_line_wizard"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "checked_firmware",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("session_id", sa.String(120), nullable=False),
        sa.Column("node_id", sa.Integer(), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("name", sa.String(300), nullable=False),
        sa.Column("kind", sa.String(8), nullable=False),
        sa.Column("image", sa.LargeBinary(), nullable=False),
        sa.Column("start_address", sa.BigInteger(), nullable=True),
        sa.Column("identity", sa.JSON(), nullable=False),
    )
    op.create_index("ix_checked_firmware_node", "checked_firmware", ["session_id", "node_id"])


def downgrade() -> None:
    op.drop_index("ix_checked_firmware_node", table_name="checked_firmware")
    op.drop_table("checked_firmware")
