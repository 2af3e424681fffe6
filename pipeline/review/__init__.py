"""The human review queue of stage 3: database, workflow, API, statistics, audit, export.

Modules: db (tables, engine), fields (validation, agreement), workflow (leases, reviews),
adjudication, enqueue (revisions), auth (tokens, sessions, CSRF), views (what each person
sees), api (FastAPI app), media (safe file access), stats/report (agreement, model
quality), audit (append-only log), export (final records), cli (`recover review`).
Importing the package imports nothing heavy.
"""
