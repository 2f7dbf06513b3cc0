# The few verbs a newcomer needs. Everything sets itself up on first use.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
BENCH ?= full

.PHONY: run test bench lint format clean cluster-up cluster-down

$(STAMP): pyproject.toml requirements.lock
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
	touch $(STAMP)

## run: set up everything and start the whole system (web, workers, simulated fleet, Redis) on http://127.0.0.1:8000,
## each process restarted when it dies; Ctrl-C stops everything (status 0)
run: $(STAMP)
	$(PY) -m fleet.run

JS_PROBE := tests/simworker/js/node_modules/.package-lock.json

# The npm roslib client the simulator is tested against (skipped, with a note, where npm is missing).
$(JS_PROBE): tests/simworker/js/package.json
	-command -v npm >/dev/null && npm install --silent --no-audit --no-fund --prefix tests/simworker/js

## test: set up everything and run the whole test suite (browser tests where chromium exists)
test: $(STAMP) $(JS_PROBE)
	$(PY) -m fleet.testrun

## bench: the paper's experiments and the scale benchmarks; results under bench/results/ (BENCH=quick: under 5 min)
bench: $(STAMP)
	$(PY) -m bench.run --$(BENCH)

## cluster-up: a multi-host fleet on this machine (root): network namespaces db, web1, web2, exec1, exec2, sim1, sim2,
## links on a private bridge (deploy/cluster.py; ROBOTS=N per simulator shard); web on http://10.77.0.11:8000/
ROBOTS ?= 10
cluster-up: $(STAMP)
	$(PY) -m deploy.cluster up --robots-per-shard $(ROBOTS)

## cluster-down: remove every process, namespace, veth and the bridge cluster-up made (idempotent)
cluster-down:
	$(PY) -m deploy.cluster down

## lint: style (ruff) and the layers of docs/ARCHITECTURE.md (import-linter; tests/test_architecture.py runs it too)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

clean:
	rm -rf var/*.sqlite3 var/*.sock var/static var/appendonly.aof var/log var/supervisord.*
