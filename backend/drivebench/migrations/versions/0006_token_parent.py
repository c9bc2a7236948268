"""API tokens remember the token that made them (issue 28 item 13): a token minted with a token ends when that
one is revoked

Revision ID: 0006_token_parent
Revises: 0005_shared_state
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006_token_parent"
down_revision = "0005_shared_state"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("api_token") as batch:
        batch.add_column(sa.Column("parent_id", sa.Integer(), nullable=True))
        batch.create_foreign_key("fk_api_token_parent", "api_token", ["parent_id"], ["id"], ondelete="CASCADE")
        batch.create_index("ix_api_token_parent_id", ["parent_id"])


def downgrade() -> None:
    with op.batch_alter_table("api_token") as batch:
        batch.drop_index("ix_api_token_parent_id")
        batch.drop_constraint("fk_api_token_parent", type_="foreignkey")
        batch.drop_column("parent_id")
