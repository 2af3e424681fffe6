"""The queue-order index holds the open items only (a partial index, `ix_items_queue_open`:
status pending, leased or reviewed, written as none of the others), so that the next open item
is found in its first rows however many items have closed: with the full index of 0004,
`POST /api/queue/next` read past every closed item first (0.7 ms of CPU per request with none
closed, 4 ms with 6 000 closed; SQLite, 10 000 items). Not the fast lane's `ix_items_open_queue`
that 0002 dropped (an `IN`, which SQLite's planner served from the status index unless told not to).

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

# `db.IS_COLLECTING`, as written at this revision
_OPEN = sa.text("status NOT IN ('conflict', 'adjudicating', 'final', 'superseded')")


def upgrade() -> None:
    op.create_index("ix_items_queue_open", "items", ["quarantined", sa.desc(sa.column("n_reviews")), "id"],
                    sqlite_where=_OPEN, postgresql_where=_OPEN)
    op.drop_index("ix_items_queue", table_name="items")


def downgrade() -> None:
    op.create_index("ix_items_queue", "items", ["quarantined", sa.desc(sa.column("n_reviews")), "id"])
    op.drop_index("ix_items_queue_open", table_name="items")
