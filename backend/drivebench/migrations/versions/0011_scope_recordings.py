"""Scope recordings (issue 31): channels, trigger, markers, the nodes' parameter-set reference and the samples,
packed in one binary column

Revision ID: 0011_scope_recordings
Revises: 0010_line_project
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011_scope_recordings"
down_revision = "0010_line_project"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "scope_recording",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("session_id", sa.String(120), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("created_by", sa.String(120), nullable=False),
        sa.Column("source", sa.String(20), nullable=False),
        sa.Column("period_s", sa.Float(), nullable=False),
        sa.Column("channels", sa.JSON(), nullable=False),
        sa.Column("trigger", sa.JSON(), nullable=False),
        sa.Column("markers", sa.JSON(), nullable=False),
        sa.Column("nodes", sa.JSON(), nullable=False),
        sa.Column("count", sa.Integer(), nullable=False),
        sa.Column("samples", sa.LargeBinary(), nullable=False),
    )
    op.create_index("ix_scope_recording_created", "scope_recording", ["created"])


def downgrade() -> None:
    op.drop_index("ix_scope_recording_created", table_name="scope_recording")
    op.drop_table("scope_recording")
