# propwatch: `make demo` and `make test` work on a fresh machine.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DATA ?= ../shared/data
OUT ?= out

.PHONY: setup demo test lint bench models propellers classifier crazypad clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# torch first, exactly pinned: here it takes the local CPU wheel (a looser pin pulls GBs of CUDA).
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[offline,fleet,dev]'
	touch $(STAMP)

setup: $(STAMP)

# The main job on shipped models and bundled data: simulate a faulty flight,
# diagnose it with the shipped classifier, and diagnose a real log.
demo: $(STAMP)
	$(BIN)/python -m offline.demo --out $(OUT)/demo --data $(DATA)

test: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check monitor offline fleet tests bench
	$(BIN)/ruff format --check monitor offline fleet tests bench

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

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
