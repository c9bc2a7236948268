"""line_project: a whole line (issue 32): the planned network it made, the project file's body as JSON

Revision ID: 0010_line_project
Revises: 0009_scope_restore
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010_line_project"
down_revision = "0009_scope_restore"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "line_project",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("network_id", sa.Integer(), sa.ForeignKey("planned_network.id", ondelete="SET NULL"),
                  nullable=True),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated", sa.DateTime(timezone=True), nullable=False),
        sa.Column("body", sa.JSON(), nullable=False),
    )
    op.create_index("ix_line_project_name", "line_project", ["name"])


def downgrade() -> None:
    op.drop_index("ix_line_project_name", table_name="line_project")
    op.drop_table("line_project")
