# pathrl — the two user-facing commands are `make reproduce-tables` and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export OMP_NUM_THREADS ?= 1

.PHONY: setup test lint bench reproduce-tables table datasets view-demo clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# torch first, pinned: this resolves to the local CPU build (any other spec pulls a CUDA build).
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[dev]'
	# torchrl's TD3 loss for the industrial waypoint policy (pathrl/industrial/rl.py). torchrl 0.14.1 pins
	# tensordict<0.15 but runs with rsl-rl's 0.15.3 (tests/test_industrial_rl.py): installed without its pins.
	$(PY) -m pip install -q --no-deps torchrl==0.14.1 hoptorch==0.1.4
	touch $(STAMP)

# Two pytest workers, one per core of the reference machine (most tests run one single-threaded training or
# evaluation); TEST_WORKERS=0 runs in one process.
TEST_WORKERS ?= 2
test: setup
	$(PY) -m pytest -n $(TEST_WORKERS) --dist worksteal

lint: setup
	$(VENV)/bin/ruff check pathrl tests tools

bench: setup
	$(PY) tools/bench.py

reproduce-tables: setup
	$(PY) tools/reproduce_tables.py $(if $(PROFILE),--profile $(PROFILE)) $(if $(TRAIN),--train) $(if $(JOBS),--jobs $(JOBS))

# One table: `make table T=II` evaluates the rows of sweeps/table_II.yaml (T=table_II and T=greedy_follower work too)
# and renders every table into results/, the others from the results already there.
table: setup
	@test -n "$(T)" || { echo "usage: make table T=II (a table of sweeps/: $$(ls sweeps | sed 's/\.yaml//' | xargs))" >&2; exit 2; }
	$(PY) tools/reproduce_tables.py --only $(if $(wildcard sweeps/$(T).yaml),$(T),table_$(T)) \
		$(if $(PROFILE),--profile $(PROFILE)) $(if $(TRAIN),--train) $(if $(JOBS),--jobs $(JOBS)) $(if $(REUSE),--reuse)

view-demo: setup
	tools/view_demo.sh

clean:
	rm -rf outputs multirun .pytest_cache
