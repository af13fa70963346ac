"""Flights of the evaluation-only simulator (``offline/evalsim``) for tests: each ``FlightSpec`` flown once per test
session, and every flight the session's selected tests declared flown together in one batch.

evalsim integrates a batch vectorised over flights, so a step costs little more for a dozen flights than for one,
and a flight is the same, array for array, whichever flights and durations it is batched with
(``tests/test_evalsim.py::test_flight_is_deterministic_and_independent_of_its_batch``).
A test module declares, when it is imported, the specs a fixture of it will fly (``declare``); the first fixture of
the session that asks for flights (``simulate_flights``, or ``write_set`` and ``evalsim_set`` under ``shared()``)
flies every declared flight that a selected test needs, and later fixtures read theirs from the cache. A spec that
was not declared is flown when asked, alone, as ``offline.evalsim.flight.simulate_flights`` would fly it.
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Callable

_DECLARED: dict[str, Callable[[], list]] = {}  # "module::fixture" -> the specs that fixture flies
_SELECTED: set[str] | None = None  # "module::fixture" of the session's selected tests (None: unknown, fly all)
_FLOWN: dict = {}  # FlightSpec -> its one-flight FlightLog
_EVALSIM: dict[str, Callable] = {}  # "fly": offline.evalsim.flight.simulate_flights, kept while shared() replaces it
BATCH = 32  # flights integrated together, as offline.evalsim.sets flies a set (memory ~ BATCH * duration)


def declare(module: str, fixture: str, specs: Callable[[], list]) -> None:
    """``fixture`` of test module ``module`` will fly the FlightSpecs ``specs()`` returns (called when first needed)."""
    _DECLARED[f"{module}::{fixture}"] = specs


def note_selected(items) -> None:
    """Record which declared fixtures the session's selected tests use (tests/conftest.py, after collection)."""
    global _SELECTED
    _SELECTED = {f"{it.module.__name__}::{f}" for it in items if getattr(it, "module", None) for f in it.fixturenames}


def _batch_key(spec) -> tuple:
    a = spec.airframe  # offline.evalsim.flight.simulate_flights: one batch shares the nominal vehicle and controller
    return (a.rotor_positions_frd_m, a.rotor_spin, a.kf_n_per_rad_s2, spec.nominal, spec.controller_gains)


def _fly(specs: list) -> None:
    import offline.evalsim.flight

    fly = _EVALSIM.get("fly", offline.evalsim.flight.simulate_flights)
    groups: dict[tuple, list] = {}
    for s in dict.fromkeys(specs):
        if s not in _FLOWN:
            groups.setdefault(_batch_key(s), []).append(s)
    for group in groups.values():
        for b in range(0, len(group), BATCH):
            chunk = group[b : b + BATCH]
            for s, log in zip(chunk, fly(chunk), strict=True):
                _FLOWN[s] = log


def simulate_flights(specs: list) -> list:
    """``offline.evalsim.flight.simulate_flights(specs)``, each flight flown once per session (a copy each call)."""
    specs = list(specs)
    if any(s not in _FLOWN for s in specs):
        wanted = list(specs)
        for key, make in _DECLARED.items():
            if _SELECTED is None or key in _SELECTED:
                try:
                    wanted += make()
                except Exception:  # noqa: BLE001 - that fixture fails on its own when it asks, with its own error
                    continue
        _fly(wanted)
    return [copy.deepcopy(_FLOWN[s]) for s in specs]


@contextlib.contextmanager
def shared():
    """Within it, ``offline.evalsim`` flies through the session's cache (``write_set``, ``alerts.flights.evalsim_set``)."""
    import pytest

    import offline.evalsim.flight
    import offline.evalsim.sets

    _EVALSIM.setdefault("fly", offline.evalsim.flight.simulate_flights)  # before it is replaced: _fly flies with it
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(offline.evalsim.flight, "simulate_flights", simulate_flights)
        mp.setattr(offline.evalsim.sets, "simulate_flights", simulate_flights)
        yield
