"""line_wizard_run: a run of the "New line" wizard (issue 32 step 4): its session, line project and the steps'
state and results as JSON, so a run resumes after a server restart

Revision ID: 0012_line_wizard
Revises: 0011_scope_recordings
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0012_line_wizard"
down_revision = "0011_scope_recordings"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "line_wizard_run",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("session_id", sa.String(120), nullable=False),
        sa.Column("project_id", sa.Integer(), sa.ForeignKey("line_project.id", ondelete="SET NULL"), nullable=True),
        sa.Column("created_by", sa.String(120), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated", sa.DateTime(timezone=True), nullable=False),
        sa.Column("body", sa.JSON(), nullable=False),
    )
    op.create_index("ix_line_wizard_run_session_id", "line_wizard_run", ["session_id"])


def downgrade() -> None:
    op.drop_index("ix_line_wizard_run_session_id", table_name="line_wizard_run")
    op.drop_table("line_wizard_run")
