"""The import graph keeps its shape (``python -m bench.house_counts``): no cycle between modules, none between
offline's packages, no import against the layering, and every offline package placed in ``OFFLINE_LAYERS``."""

from __future__ import annotations

from bench.house_counts import counts


def test_the_import_graph_has_no_cycle_and_no_arrow_back_up():
    c = counts()
    assert c["cycles"] == []
    assert c["arrows back up"] == []
    assert c["offline package cycles"] == []
    assert c["offline arrows back up"] == []
    assert c["offline packages without a layer"] == []
