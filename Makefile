# libero-recover. Two commands do everything on a fresh machine:
#   make demo   set up, then `recover run` on the small embedded config: stage 1 -> 2 -> 3, then
#               it stops at human review; `make run` again after review finishes release, demos, export
#   make test   set up (with the test browser), then the whole test suite
# The order of the steps is declared once, in pipeline/flow.py (STEPS); each target below runs one alone.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
RECOVER := $(VENV)/bin/recover
CONFIG ?= configs/smoke.yaml
# real-simulator tests run in parallel, one worker per core
PYTEST_WORKERS ?= 2

.PHONY: setup setup-test demo run test stage1 rerender stage2 stage3 review-status review-serve review-export bench-review release verify reproduce demos export-lerobot eval tasks bench clean

# setup is idempotent: the stamp re-runs it only when its inputs change
$(VENV)/.setup-stamp: pyproject.toml requirements/sim.txt scripts/setup.sh
	bash scripts/setup.sh
	touch $@

setup: $(VENV)/.setup-stamp

$(VENV)/.setup-test-stamp: $(VENV)/.setup-stamp requirements/lerobot.txt pipeline/lerobot_env/lerobot_compat.py scripts/setup_lerobot.sh
	WITH_BROWSER=1 WITH_LEROBOT=1 WITH_POSTGRES=1 bash scripts/setup.sh
	touch $@

setup-test: $(VENV)/.setup-test-stamp

demo: setup
	$(RECOVER) run --config $(CONFIG)
	$(RECOVER) review status --config $(CONFIG)

run: setup
	$(RECOVER) run --config $(CONFIG)

test: setup-test
	$(VENV)/bin/pytest -n $(PYTEST_WORKERS) --dist loadgroup -q

stage1: setup
	$(RECOVER) stage1 --config $(CONFIG)

# redraw an existing run's frames with the current renderer (no physics)
rerender: setup
	$(RECOVER) stage1 --rerender --config $(CONFIG)

stage2: setup
	$(RECOVER) stage2 --config $(CONFIG)

stage3: setup
	$(RECOVER) stage3 --config $(CONFIG)

review-status: setup
	$(RECOVER) review status --config $(CONFIG)

review-serve: setup
	$(RECOVER) review serve --config $(CONFIG)

review-export: setup
	$(RECOVER) review export --config $(CONFIG)

# p95 latency of the review page and decision POST with 20 concurrent reviewers; lost decisions
bench-review: setup
	$(PY) benchmarks/review_load.py

release: setup
	$(RECOVER) release --config $(CONFIG)

verify: setup
	$(RECOVER) verify $(or $(DIR),runs/smoke/release)

reproduce: setup
	$(RECOVER) reproduce --config $(CONFIG)

demos: setup
	$(RECOVER) demos --config $(CONFIG)

export-lerobot: setup
	$(RECOVER) export-lerobot --config $(CONFIG)

eval: setup
	$(RECOVER) eval --config $(CONFIG)

tasks: setup
	$(RECOVER) tasks

clean:
	rm -rf runs/smoke
