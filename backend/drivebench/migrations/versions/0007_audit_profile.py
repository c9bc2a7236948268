"""The audit log names the profile a write was sent with (issue 30 item 5): undo of a write is refused when the node
is handled with another profile since

Revision ID: 0007_audit_profile
Revises: 0006_token_parent
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007_audit_profile"
down_revision = "0006_token_parent"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.add_column(sa.Column("profile", sa.String(120), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("audit_log") as batch:
        batch.drop_column("profile")
