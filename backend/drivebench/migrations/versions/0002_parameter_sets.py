"""parameter sets (with versions), downloads (values read first + report), audit log of every write

Revision ID: 0002_parameter_sets
Revises: 0001_planned_network
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002_parameter_sets"
down_revision = "0001_planned_network"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "parameter_set",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("profile_id", sa.String(120), nullable=False),
        sa.Column("profile_version", sa.String(40), nullable=False),
        sa.Column("device", sa.String(200), nullable=False),
        sa.Column("node_id", sa.Integer(), nullable=True),
        sa.Column("session_id", sa.String(120), nullable=True),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated", sa.DateTime(timezone=True), nullable=False),
        sa.Column("created_by", sa.String(120), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
    )
    op.create_index("ix_parameter_set_name", "parameter_set", ["name"])
    op.create_index("ix_parameter_set_profile_id", "parameter_set", ["profile_id"])
    op.create_table(
        "parameter_set_version",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("set_id", sa.Integer(), sa.ForeignKey("parameter_set.id", ondelete="CASCADE"), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("created", sa.DateTime(timezone=True), nullable=False),
        sa.Column("created_by", sa.String(120), nullable=False),
        sa.Column("reason", sa.String(300), nullable=False),
        sa.Column("count", sa.Integer(), nullable=False),
        sa.Column("body", sa.JSON(), nullable=False),
        sa.UniqueConstraint("set_id", "version", name="uq_parameter_set_version"),
    )
    op.create_index("ix_parameter_set_version_set_id", "parameter_set_version", ["set_id"])
    op.create_table(
        "parameter_download",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("kind", sa.String(20), nullable=False),
        sa.Column("set_id", sa.Integer(), sa.ForeignKey("parameter_set.id", ondelete="SET NULL"), nullable=True),
        sa.Column("set_version", sa.Integer(), nullable=True),
        sa.Column("session_id", sa.String(120), nullable=False),
        sa.Column("node_id", sa.Integer(), nullable=False),
        sa.Column("profile_id", sa.String(120), nullable=False),
        sa.Column("user", sa.String(120), nullable=False),
        sa.Column("started", sa.DateTime(timezone=True), nullable=False),
        sa.Column("finished", sa.DateTime(timezone=True), nullable=True),
        sa.Column("state", sa.String(20), nullable=False),
        sa.Column("before", sa.JSON(), nullable=False),
        sa.Column("report", sa.JSON(), nullable=False),
    )
    op.create_table(
        "audit_log",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("time", sa.DateTime(timezone=True), nullable=False),
        sa.Column("user", sa.String(120), nullable=False),
        sa.Column("session_id", sa.String(120), nullable=False),
        sa.Column("node_id", sa.Integer(), nullable=False),
        sa.Column("ref", sa.String(60), nullable=False),
        sa.Column("address", sa.String(20), nullable=False),
        sa.Column("old_value", sa.Text(), nullable=True),
        sa.Column("new_value", sa.Text(), nullable=False),
        sa.Column("result", sa.String(20), nullable=False),
        sa.Column("detail", sa.Text(), nullable=True),
        sa.Column("origin", sa.String(60), nullable=False),
    )
    op.create_index("ix_audit_log_time", "audit_log", ["time"])
    op.create_index("ix_audit_log_node_id", "audit_log", ["node_id"])


def downgrade() -> None:
    op.drop_index("ix_audit_log_node_id", table_name="audit_log")
    op.drop_index("ix_audit_log_time", table_name="audit_log")
    op.drop_table("audit_log")
    op.drop_table("parameter_download")
    op.drop_index("ix_parameter_set_version_set_id", table_name="parameter_set_version")
    op.drop_table("parameter_set_version")
    op.drop_index("ix_parameter_set_profile_id", table_name="parameter_set")
    op.drop_index("ix_parameter_set_name", table_name="parameter_set")
    op.drop_table("parameter_set")
