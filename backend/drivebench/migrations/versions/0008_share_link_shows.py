"""A share link stores what it shows (issue 30 item 6): health, faults, emergencies, parameters, bus; links made
before show what they showed (health) and the faults, the default of a new link

Revision ID: 0008_share_link_shows
Revises: 0007_audit_profile
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008_share_link_shows"
down_revision = "0007_audit_profile"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("share_link") as batch:
        batch.add_column(sa.Column("shows", sa.String(200), nullable=False, server_default="health,faults"))


def downgrade() -> None:
    with op.batch_alter_table("share_link") as batch:
        batch.drop_column("shows")
