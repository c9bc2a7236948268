"""Shared state of the servers of one database: share links, signed-out sessions and failed sign-ins move out of
the server's memory, so every server honours them and a restart keeps them

Revision ID: 0005_shared_state
Revises: 0004_session_stamp
Create Date: 2026-11-25
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005_shared_state"
down_revision = "0004_session_stamp"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("parameter_download") as batch:
        batch.add_column(sa.Column("server", sa.String(120), nullable=True))
    op.create_table(
        "share_link",
        sa.Column("id", sa.String(16), primary_key=True),
        sa.Column("token_hash", sa.String(64), nullable=False, unique=True),
        sa.Column("hint", sa.String(16), nullable=False),
        sa.Column("label", sa.String(80), nullable=False),
        sa.Column("created", sa.Float(), nullable=False),
        sa.Column("expires", sa.Float(), nullable=False, index=True),
    )
    op.create_table(
        "signed_out_session",
        sa.Column("sid", sa.String(64), primary_key=True),
        sa.Column("until", sa.Float(), nullable=False, index=True),
    )
    op.create_table(
        "sign_in_failure",
        sa.Column("key", sa.String(300), primary_key=True),
        sa.Column("count", sa.Integer(), nullable=False),
        sa.Column("locked_until", sa.Float(), nullable=False),
        sa.Column("last", sa.Float(), nullable=False, index=True),
    )


def downgrade() -> None:
    op.drop_table("sign_in_failure")
    op.drop_table("signed_out_session")
    op.drop_table("share_link")
    with op.batch_alter_table("parameter_download") as batch:
        batch.drop_column("server")
