"""The classifier gain of calibration: one recipe, trained on nominal-sim vs calibrated-sim data.

``classifier_gain`` trains the fault classifier (``offline.classifier.train``,
the classifier engineer's recipe) twice, on a data set simulated with the
nominal vehicle and on the same data set simulated with the calibrated one,
and scores both on labelled measured flights.

``python -m offline.calibrate.gain`` runs the experiment end to end where the
"real" vehicle is a simulated one with hidden terms (the paper's situation: an
off-centre CG and an unequal motor), since no labelled real flights of the
paper's vehicle exist: it calibrates on two healthy flights of that vehicle,
then compares the two classifiers on its labelled faulty flights. It prints
the figures as JSON; it takes a few minutes on one core.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

from monitor.vehicle import DEFAULT_VEHICLE, VehicleConfig, load_vehicle
from offline.calibrate.calibrate import calibrate_vehicle
from offline.classifier.evaluate import evaluate_dataset
from offline.classifier.train import TrainConfig, predict_probabilities, train
from offline.dataset.generate import DatasetSpec, generate
from offline.dataset.records import FaultDataset


def classifier_gain(
    measured: FaultDataset,
    nominal: VehicleConfig,
    calibrated: VehicleConfig,
    spec: DatasetSpec,
    cfg: TrainConfig,
    hop: int = 10,
    log=print,
) -> dict:
    out: dict = {"measured_flights": measured.n_flights, "train_spec": dataclasses.asdict(spec)}
    for name, vehicle in (("nominal", nominal), ("calibrated", calibrated)):
        ds = generate(dataclasses.replace(spec, name=f"{spec.name}-{name}"), vehicle, log=log)
        model = train(ds, cfg, log=log)
        r = evaluate_dataset(
            lambda x, m=model: predict_probabilities(m, x),
            measured,
            cfg.features,
            cfg.window,
            hop,
            name=f"{measured.name} by {name}-sim classifier",
        )
        out[name] = {"accuracy": r.accuracy, "windows": r.windows, "per_propeller_accuracy": list(r.per_propeller_accuracy)}
    out["accuracy_gain"] = out["calibrated"]["accuracy"] - out["nominal"]["accuracy"]
    return out


def experiment(flights_per_label: int = 2, duration_s: float = 40.0, epochs: int = 4, seed: int = 0, log=print) -> dict:
    nominal = load_vehicle(DEFAULT_VEHICLE)
    truth = dataclasses.replace(nominal, cg_offset_frd_m=(0.02, -0.015, 0.0), motor_efficiency=(1.0, 0.92, 1.0, 1.0))
    base = DatasetSpec(
        name="gain",
        fault="bent",
        waypoints=("random",),
        flights_per_label=flights_per_label,
        duration_s=duration_s,
        propellers="quadratic",
        seed=seed,
    )
    # Calibration flights: two healthy flights of the "real" vehicle.
    from offline.sim.mission import random_waypoints
    from offline.sim.propeller import QuadraticPropeller
    from offline.sim.simulator import SimConfig, simulate

    sim = simulate(
        truth,
        random_waypoints(2, 5, seed=seed + 100),
        QuadraticPropeller.for_vehicle(truth),
        SimConfig(duration_s=60.0),
        seed=seed + 100,
    )
    result = calibrate_vehicle([sim.to_flight_table(i, source=f"healthy-{i}") for i in range(2)], nominal)
    log(f"calibration: cause {result.cause}, findings {[(f['effect'], f['params']) for f in result.findings]}")
    measured = generate(dataclasses.replace(base, name="measured", seed=seed + 200), truth, log=log)
    cfg = TrainConfig(epochs=epochs, seed=seed)
    gain = classifier_gain(measured, nominal, result.calibrated, dataclasses.replace(base, seed=seed + 300), cfg, log=log)
    gain["calibration"] = {
        "cause": result.cause,
        "findings": [{k: f[k] for k in ("effect", "params", "score")} for f in result.findings],
        "hidden": {"cg_offset_frd_m": truth.cg_offset_frd_m, "motor_efficiency": truth.motor_efficiency},
    }
    return gain


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m offline.calibrate.gain", description=__doc__.split("\n\n")[0])
    p.add_argument("--flights-per-label", type=int, default=2)
    p.add_argument("--duration-s", type=float, default=40.0)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    out = experiment(a.flights_per_label, a.duration_s, a.epochs, a.seed, log=lambda m: print(m, file=sys.stderr))
    print(json.dumps(out, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
