"""Leases remember when they were taken (`taken_at`), so that renewing one never holds an
item past the queue's maximum lease lifetime; a lease of an older database counts as taken
when it was last due to expire (it can still be renewed up to that maximum from then).

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("leases", sa.Column("taken_at", sa.Float(), nullable=True))
    op.execute("UPDATE leases SET taken_at = expires_at")
    with op.batch_alter_table("leases") as batch:
        batch.alter_column("taken_at", existing_type=sa.Float(), nullable=False)


def downgrade() -> None:
    with op.batch_alter_table("leases") as batch:
        batch.drop_column("taken_at")
