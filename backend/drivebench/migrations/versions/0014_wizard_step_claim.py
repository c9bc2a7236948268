"""wizard_step_claim: the step of a "New line" wizard run that a server process runs now, and until when its lease
holds (issue 32 item 7 with several servers on one database): another server sees the step running and does not start
it, and reads it interrupted once the holder stopped renewing

Revision ID: 0014_wizard_step_claim
Revises: 0013_checked_firmware
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0014_wizard_step_claim"
down_revision = "0013_checked_firmware"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("line_wizard_run") as batch:
        batch.add_column(sa.Column("step_claim", sa.String(32), nullable=True))
        batch.add_column(sa.Column("step_name", sa.String(20), nullable=True))
        batch.add_column(sa.Column("step_server", sa.String(120), nullable=True))
        batch.add_column(sa.Column("step_since", sa.Float(), nullable=True))
        batch.add_column(sa.Column("step_lease_until", sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("line_wizard_run") as batch:
        for column in ("step_lease_until", "step_since", "step_server", "step_name", "step_claim"):
            batch.drop_column(column)
