"""One service layer: the fast lane's open-queue index goes (nothing reads it); the audit
log becomes append-only on PostgreSQL too (SQLite had its triggers from the start).

Revision ID: 0002
Revises: 0001
"""

from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        op.execute("DROP INDEX IF EXISTS ix_items_open_queue")
    elif op.get_bind().dialect.name == "postgresql":
        op.execute("CREATE OR REPLACE FUNCTION events_append_only() RETURNS trigger LANGUAGE plpgsql AS "
                   "$$ BEGIN RAISE EXCEPTION 'the audit log is append-only'; END $$")
        for verb in ("update", "delete"):
            op.execute(f"CREATE TRIGGER events_no_{verb} BEFORE {verb.upper()} ON events "
                       "FOR EACH ROW EXECUTE FUNCTION events_append_only()")


def downgrade() -> None:
    if op.get_bind().dialect.name == "postgresql":
        op.execute("DROP TRIGGER IF EXISTS events_no_update ON events")
        op.execute("DROP TRIGGER IF EXISTS events_no_delete ON events")
        op.execute("DROP FUNCTION IF EXISTS events_append_only()")
