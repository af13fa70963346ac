# propwatch: `make demo` and `make test` work on a fresh machine.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DATA ?= ../shared/data
OUT ?= out

.PHONY: setup demo test lint bench models propellers classifier crazypad clean calibrate-alerts evaluate-alerts

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# torch first, exactly pinned: here it takes the local CPU wheel (a looser pin pulls GBs of CUDA).
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[offline,dev]'
	touch $(STAMP)

setup: $(STAMP)

# The main job on shipped models and bundled data: simulate a faulty flight,
# diagnose it with the shipped classifier, and diagnose a real log.
demo: $(STAMP)
	$(BIN)/python -m offline.demo --out $(OUT)/demo --data $(DATA)

test: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check monitor offline tests bench
	$(BIN)/ruff format --check monitor offline tests bench

bench: $(STAMP)
	for b in bench/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# Rebuild the shipped models (minutes to an hour on 2 cores; not run by tests).
propellers: $(STAMP)
	$(BIN)/propwatch train-propellers --out models/propellers

classifier: $(STAMP)
	$(BIN)/python -m offline.classifier.build_shipped --out models

models: propellers classifier

# Sim-to-real on the real CrazyPAD flights (about 15 min on 2 cores): calibrate, simulate, train,
# diagnose every held-out flight; --ship refreshes models/crazyflie-classifier.onnx.
crazypad: $(STAMP)
	$(BIN)/propwatch crazypad run --data $(DATA)/crazypad --out $(OUT)/crazypad --ship

# Alert decisions (issue 13; docs/ALERTS.md). calibrate-alerts rewrites models/decision-calibration.json from
# healthy randomised flights (HOURS); evaluate-alerts scores the rules on independent flights and writes
# $(OUT)/alerts/alerts.{json,md} for the card. The issue's size is the default (10 h healthy, 200 onsets):
# hours of CPU on 2 cores; e.g. `make evaluate-alerts ALERT_ARGS="--healthy-hours 1 --onset-flights 64"`.
HOURS ?= 2
ALERT_ARGS ?=
calibrate-alerts: $(STAMP)
	$(BIN)/python -m offline.alerts.evaluate --calibrate --calibration-hours $(HOURS) --healthy-hours 0.05 --onset-flights 4 --out $(OUT)/alerts-calibration

evaluate-alerts: $(STAMP)
	$(BIN)/python -m offline.alerts.evaluate --out $(OUT)/alerts $(ALERT_ARGS)

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
