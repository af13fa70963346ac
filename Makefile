# propwatch: `make demo` and `make test` work on a fresh machine.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DATA ?= ../shared/data
OUT ?= out

.PHONY: setup demo test lint bench bench-measure models propellers classifier crazypad clean tune-noise evaluate-physics dataset-randomised card card-text tune-alerts evaluate-alerts evaluate-torque-sign evaluate-calibration tune-memory evaluate-memory
# Former target names, kept as aliases of the targets that follow the commands.
.PHONY: calibrate-physics calibrate-alerts calibrate-memory

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
	$(BIN)/ruff check monitor offline fleet tests bench examples
	$(BIN)/ruff format --check monitor offline fleet tests bench examples

# Every script in bench/ runs as a module from the repository root (python -m bench.<name>). `make bench` runs
# the bench_* timings and the import-graph counts; `make bench-measure` the scripts that measured shipped constants
# and cards, each with its defaults and outputs under $(OUT)/bench (minutes to an hour; CrazyPAD ones need its data).
BENCH ?= $(sort $(basename $(notdir $(wildcard bench/bench_*.py)))) house_counts
BENCH_MEASURE ?= alerts_flights decision_constants crazypad_baseline crazypad_fusion crazypad_fusion_sim crazypad_separation response_gain_sim
bench: $(STAMP)
	for b in $(BENCH); do echo "== bench.$$b"; $(BIN)/python -m bench.$$b || exit 1; done

bench-measure: $(STAMP)
	mkdir -p $(OUT)/bench
	for b in $(BENCH_MEASURE); do echo "== bench.$$b"; $(BIN)/python -m bench.$$b || exit 1; done
	$(BIN)/python -m bench.crazypad_adapt --out $(OUT)/bench/crazypad-adapt
	$(BIN)/python -m bench.evalsim_hidden --out $(OUT)/bench/evalsim-hidden
	$(BIN)/python -m bench.evalsim_lag --out $(OUT)/bench/evalsim-lag

# Rebuild the shipped models (minutes to an hour on 2 cores; not run by tests).
propellers: $(STAMP)
	$(BIN)/propwatch train-propellers --out models/propellers

classifier: $(STAMP)
	$(BIN)/python -m offline.classifier.build_shipped --out models

models: propellers classifier

# The shipped classifier's training set: every flight's physics drawn from the register of unmeasured
# assumptions (offline/sim/assumptions.py), the airframe's own terms (CG, motor spread, arm and ESC errors)
# at nominal, as for an airframe `propwatch adapt` calibrated; 60 flights per label of 80 s (a few minutes of
# CPU). AIRFRAME=drawn draws those too (an unmeasured airframe). Smaller: make dataset-randomised FLIGHTS=2 DURATION=40
FLIGHTS ?= 60
DURATION ?= 80
AIRFRAME ?= nominal
SEED ?= 7
NAME ?= RN
RANDOMISED_OUT ?= $(OUT)/data-randomised
# ASSUME='*_torque_per_thrust_change_*=-0.10,0': move register ranges (a stress set of our own simulator, see conformal).
ASSUME ?=
dataset-randomised: $(STAMP)
	$(BIN)/propwatch dataset --name $(NAME) --waypoints random --payload 0,0.6 --fault varied --physics randomised \
		--airframe $(AIRFRAME) --propellers quadratic --flights-per-label $(FLIGHTS) --duration $(DURATION) --seed $(SEED) \
		--out $(RANDOMISED_OUT) $(foreach a,$(ASSUME),--assumption '$(a)')

# Every figure of models/classifier.card.md from nothing: the paper sets, the ablation's training sets,
# every ablation row, then the shipped model from the last row's checkpoint, its onboard figures and the
# card (many hours on 2 cores: 16 trainings). The card reads only models/classifier.manifest.json and
# models/classifier.card-tables.json, which this writes; `make card-text` rewrites the card from them.
CARD := $(OUT)/card
RSET := --name R --waypoints random --payload 0,0.6 --wind 3 --variants 8 --seed 7
card: $(STAMP)
	$(BIN)/propwatch dataset --sets A,B,C --fault bent,cracked --flights-per-label 5 --out $(CARD)/data30
	$(BIN)/propwatch dataset $(RSET) --fault mixed --flights-per-label 20 --out $(CARD)/data30
	$(BIN)/propwatch dataset $(RSET) --fault varied --flights-per-label 30 --out $(CARD)/data30
	$(BIN)/python -m offline.classifier.experiments --data $(CARD)/data30 --out $(CARD)/experiments --only base
	mkdir -p $(CARD)/data60 && cp $(CARD)/data30/[ABC]-*.npz $(CARD)/data30/[ABC]-*.manifest.json $(CARD)/data60/
	$(BIN)/propwatch dataset $(RSET) --fault varied --flights-per-label 60 --out $(CARD)/data60
	$(BIN)/python -m offline.classifier.experiments --data $(CARD)/data60 --out $(CARD)/experiments --only x60
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRN
	cp $(CARD)/data30/[ABC]-*.npz $(CARD)/data30/[ABC]-*.manifest.json $(CARD)/dataRN/
	$(BIN)/python -m offline.classifier.experiments --data $(CARD)/dataRN --out $(CARD)/experiments --only randomised
	$(BIN)/python -m offline.classifier.build_shipped --out models --data $(CARD)/dataRN --reuse \
		--ablation $(CARD)/experiments --checkpoint "$(CARD)/experiments/randomised physics x60 +yaw robust dropout.pt"
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNcal FLIGHTS=10 SEED=8 NAME=RNcal
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRRcal FLIGHTS=10 SEED=8 NAME=RRcal AIRFRAME=drawn
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNfall FLIGHTS=10 SEED=9 NAME=RNfall ASSUME='*_torque_per_thrust_change_*=-0.30,0'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNrise FLIGHTS=10 SEED=9 NAME=RNrise ASSUME='*_torque_per_thrust_change_*=0,0.30'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRRfall FLIGHTS=10 SEED=9 NAME=RRfall AIRFRAME=drawn ASSUME='*_torque_per_thrust_change_*=-0.30,0'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRRrise FLIGHTS=10 SEED=9 NAME=RRrise AIRFRAME=drawn ASSUME='*_torque_per_thrust_change_*=0,0.30'
	# beyond the register: hover losses past its largest (selection); the torque change past either end (measured only)
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNbelow FLIGHTS=10 SEED=10 NAME=RNbelow ASSUME='*_torque_per_thrust_change_*=-0.50,-0.30'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNabove FLIGHTS=10 SEED=10 NAME=RNabove ASSUME='*_torque_per_thrust_change_*=0.30,0.50'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRNsevere FLIGHTS=10 SEED=10 NAME=RNsevere ASSUME='*_thrust_loss_*_frac=0.12,0.25'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataTSup FLIGHTS=48 DURATION=60 SEED=24 NAME=TSup ASSUME='*_torque_per_thrust_change_*=0.02,0.10'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataTSdown FLIGHTS=48 DURATION=60 SEED=24 NAME=TSdown ASSUME='*_torque_per_thrust_change_*=-0.10,-0.02'
	$(MAKE) dataset-randomised RANDOMISED_OUT=$(CARD)/dataRQcal FLIGHTS=10 SEED=8 NAME=RQcal AIRFRAME=drawn \
		ASSUME='motor_efficiency_spread_frac=0.01,0.02 cg_offset_frd_m=-0.0025,0.0025 arm_position_error_m=-0.00075,0.00075 esc_offset_rpm=-37.5,37.5 healthy_torque_per_thrust_spread_frac=-0.0075,0.0075'
	$(BIN)/propwatch tune sets --model models/classifier.onnx --data $(CARD)/dataRNcal/RNcal-varied.npz \
		--data $(CARD)/dataRNfall/RNfall-varied.npz --data $(CARD)/dataRNrise/RNrise-varied.npz \
		--beyond $(CARD)/dataRNsevere/RNsevere-varied.npz \
		--check $(CARD)/dataRNbelow/RNbelow-varied.npz --check $(CARD)/dataRNabove/RNabove-varied.npz \
		--sign-check $(CARD)/dataTSup/TSup-varied.npz $(CARD)/dataTSdown/TSdown-varied.npz \
		--check $(CARD)/dataRQcal/RQcal-varied.npz \
		--check $(CARD)/dataRRcal/RRcal-varied.npz --unmeasured $(CARD)/dataRRcal/RRcal-varied.npz \
		--unmeasured $(CARD)/dataRRfall/RRfall-varied.npz --unmeasured $(CARD)/dataRRrise/RRrise-varied.npz

card-text: $(STAMP)
	$(BIN)/python -m offline.classifier.build_shipped --card-only --out models

# Sim-to-real on the real CrazyPAD flights (about 15 min on 2 cores): calibrate, simulate, train,
# diagnose every held-out flight; --ship refreshes models/crazyflie-classifier.onnx.
crazypad: $(STAMP)
	$(BIN)/propwatch crazypad run --data $(DATA)/crazypad --out $(OUT)/crazypad --ship

# Alert decisions (docs/ALERTS.md). tune-alerts (`propwatch tune alerts`) rewrites models/decision-calibration.json
# from healthy randomised flights (HOURS); evaluate-alerts scores the rules on independent flights and writes
# $(OUT)/alerts/alerts.{json,md}; `python -m offline.alerts.card $(OUT)/alerts/alerts.json` puts the table in the card.
# The default size is 10 classified healthy hours per simulator and 200 onsets: hours of CPU on 2 cores;
# e.g. `make evaluate-alerts ALERT_ARGS="--healthy-hours 1 --onset-flights 64"`.
# The shipped calibration: 10 flown hours (450 flights), thresholds at the 95 % quantile of a flight bootstrap.
HOURS ?= 10
ALERT_ARGS ?=
tune-alerts: $(STAMP)
	$(BIN)/propwatch tune alerts --calibration-hours $(HOURS) --healthy-hours 0.05 --onset-flights 4 --out $(OUT)/alerts-calibration

evaluate-alerts: $(STAMP)
	$(BIN)/propwatch evaluate alerts --out $(OUT)/alerts $(ALERT_ARGS)

# The torque-sign check: the damaged blade's torque-per-thrust change up (+2..+10 %) vs down (-10..-2 %),
# 192 singles each; fails when the shipped system's single-propeller accuracy moves by more than 2 points (~6 min).
evaluate-torque-sign: $(STAMP)
	$(BIN)/python -m bench.bench_torque_sign --flights-per-label 48 --check

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache

# Credible-set coverage of the moment-balance verdict on randomised flights of OUR simulator (about 1 min):
# `propwatch tune noise`.
tune-noise: $(STAMP)
	$(BIN)/propwatch tune noise --json $(OUT)/physics-calibration.json

# The calibrator's hidden-effect matrix (bench/evalsim_calibration.py): resolution on our simulator, then 10 effects x
# 3 sizes x 5 seeds, 60 nothing-hidden runs and outside-library effects on the evaluation-only simulator (hours on
# 2 cores). The calibrator's gates come from our simulator: python -m offline.calibrate.derive_gates.
evaluate-calibration: $(STAMP)
	nice -n 10 $(BIN)/python -m bench.evalsim_calibration --out $(OUT)/evaluate-calibration

# Vehicle memory (docs/VEHICLE_MEMORY.md). tune-memory: our simulator's same-airframe fleet (seed 1, 24 airframes,
# about 3 min) and the constants of monitor/memory/thresholds.py from it. evaluate-memory: diagnose, daemon and cost on
# the evaluation-only simulator's set `vehicles` and our fleet of seed 0, beside the references (about 30 min).
tune-memory: $(STAMP)
	$(BIN)/python -c "from offline.vehicles.ours import write_fleet; write_fleet('$(OUT)/ours_cal', 288, seed=1)"
	$(BIN)/python -m offline.vehicles.calibrate --fleet $(OUT)/ours_cal

evaluate-memory: $(STAMP)
	nice -n 10 $(BIN)/python -m bench.bench_vehicle_memory --out $(OUT)/vehicle-memory
	nice -n 10 $(BIN)/python -m bench.crazypad_memory --root $(DATA)/crazypad

# Localisation on our paper sets (physics, CNN, omega^2-share side by side; a few minutes).
evaluate-physics: $(STAMP)
	$(BIN)/python -m bench.bench_localise --json $(OUT)/localise-ours.json

calibrate-alerts: tune-alerts
calibrate-physics: tune-noise
calibrate-memory: tune-memory
