# Two commands set everything up on a fresh machine: `make demo` and `make test`.
# Both create (or refresh) the local .venv when requirements*.txt or setup.py change.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out

.PHONY: demo test test-fast lint bench clean venv nlp-cache nlp-cache-sites

venv: $(STAMP)

$(STAMP): requirements.txt requirements-test.txt setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements-test.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	touch $(STAMP)

# Both build the default NLP's compiled functions first (nlp-cache, once per machine): the failure path runs on them.
demo: $(STAMP) nlp-cache
	$(BIN)/python -m helireach_ros.cli.demo --out $(OUT)

test: $(STAMP) nlp-cache
	$(BIN)/ruff check helireach_ros test bench
	$(BIN)/mypy
	$(BIN)/python -m pytest -q --durations=25 test

# The inner loop: lint and every test but those that start ROS systems, drive Chromium, compile code or fly many
# closed loops (pytest markers; CI runs everything).
test-fast: $(STAMP)
	$(BIN)/ruff check helireach_ros test bench
	$(BIN)/mypy
	$(BIN)/python -m pytest -q -m "not (system or realtime or browser or build or slow)" test

lint: $(STAMP)
	$(BIN)/ruff check helireach_ros test bench
	$(BIN)/mypy

# Compiled NLP functions for the default airframe and settings (the momentum rotor's: ~3.5 min and ~3.6 GB with gcc
# on 2 cores, once; a no-op when cached; without them the planner uses the plain CasADi functions, whose median cold
# plan takes ~1.8x as long), and the block LDL^T linear solver (~1 s; a planner also builds it at first use).
# HELIREACH_NLP_CACHE, CC, HELIREACH_NLP_CFLAGS apply.
nlp-cache: $(STAMP)
	$(BIN)/helireach nlp-cache

# Also the landing-site and footprint NLPs (planner parameters landing_sites, footprint_period): ~3.8 min each on 2
# cores, once; without them those solves run on the plain functions (a site plan ~1.7x as long warm).
nlp-cache-sites: $(STAMP)
	$(BIN)/helireach nlp-cache --objective site --objective nearest_touchdown --objective farthest_touchdown

# The benches behind docs/results/: each writes docs/results/data/<bench>.json (--json), one after another (the
# numbers are times: never two at once), then bench/results_pages.py regenerates the pages from those records.
# About two hours on 2 cores, most of it the Monte Carlo (two objectives, two re-plan floors, 200 draws each, each
# draw's own landing), the envelope grids of envelope_resolution.py and the reach-avoid envelope slice of
# objective_statuses.py; replay_failures.py on a 9 x 7 grid (its default 17 x 13 takes ~12 minutes).
bench: $(STAMP) nlp-cache
	$(BIN)/helireach nlp-cache --objective reach_avoid  # objective_statuses and monte_carlo compare both compiled
	$(BIN)/python bench/plan_latency.py --json
	$(BIN)/python bench/failure_latency.py --json
	$(BIN)/python bench/site_latency.py --json
	$(BIN)/python bench/envelope_throughput.py --workers 1,2 --dask-local 2 --json
	$(BIN)/python bench/envelope_resolution.py --levels 1 2 4 --json
	$(BIN)/python bench/replay_failures.py --heights 9 --speeds 7 --json
	$(BIN)/python bench/closed_loop_latency.py --json
	$(BIN)/python bench/objective_statuses.py --json
	$(BIN)/python bench/monte_carlo.py --runs 200 --policies disturbance+keep --objectives terminal reach_avoid \
		--replan-min-heights 0.5 0.3 --truth-check --no-weight-check --json
	$(BIN)/python bench/results_pages.py

clean:
	rm -rf $(VENV) $(OUT) build install log *.egg-info
