"""The older share rule (``offline.adapt.share_rule``): the comparison behind the CrazyPAD card's fused figures and
``propwatch adapt``'s own check of its healthy logs. No command's verdict uses it (vehicle memory does)."""

from __future__ import annotations

import numpy as np
import pytest
from test_diagnose_fixtures import write_tlog

from monitor.labels import LABEL_TABLE, label_from_mask
from offline.adapt.share_rule import HealthyBaseline, fuse


def _probs(**by_label) -> np.ndarray:
    p = np.full(16, 0.0)
    for k, v in by_label.items():
        p[int(k[1:]) - 1] = v
    return p


def label_of(*rotors) -> int:
    return label_from_mask([i + 1 in rotors for i in range(4)])


def test_fuse_rule_by_hand():
    healthy_says = _probs(l1=0.7, l3=0.3)
    # One rotor beyond 3 spreads: that rotor, whatever the classifier said.
    f = fuse([0.5, 5.0, -1.0, -2.0], healthy_says, 1, True)
    assert (f["label"], f["faulty_propellers"], f["confidence"]) == (label_of(2), [2], "confident")
    # Exactly 3 spreads is not beyond; far *below* the share is not a damaged propeller's signature alone.
    f = fuse([3.0, -4.0, 0.0, 0.0], _probs(l2=0.6, l1=0.4), 2, False)
    assert (f["label"], f["confidence"]) == (1, "confident") and "healthy" in f["rule"]
    # No rotor beyond: a confident classifier still stands.
    assert fuse([0.0, 0.0, 0.0, 0.0], _probs(l5=0.95), 5, True)["faulty_propellers"] == [4]
    # Two rotors beyond: the classifier picks among {2}, {4}, {2, 4}; confident only with >= 0.9 of their mass.
    pair = label_of(2, 4)
    f = fuse([0.0, 4.0, 0.0, 6.0], _probs(l1=0.5, **{f"l{pair}": 0.475, f"l{label_of(4)}": 0.025}), 1, False)
    assert (f["label"], f["confidence"]) == (pair, "confident")  # 0.475 / 0.5 = 0.95
    f = fuse([0.0, 4.0, 0.0, 6.0], _probs(**{f"l{pair}": 0.3, f"l{label_of(4)}": 0.5, f"l{label_of(2)}": 0.2}), 1, False)
    assert (f["label"], f["confidence"]) == (label_of(4), "ambiguous")
    assert set(LABEL_TABLE[f["label"]]) <= {2, 4}
    with pytest.raises(ValueError, match="4 deviations and 16"):
        fuse([0.0] * 3, healthy_says, 1, True)


@pytest.fixture(scope="module")
def healthy_log(tmp_path_factory):
    return write_tlog(tmp_path_factory.mktemp("fuse") / "healthy.tlog", duration_s=12.0, faulty=None, seed=5)


def test_student_t_spreads_by_hand():
    """A new flight against the mean and std of n healthy flights: t_{n-1} at the Gaussian 3-sigma tail, times
    sqrt(1 + 1/n). By hand for n = 4: t_3.isf(0.0013499) = 9.2189 (tables), times sqrt(1.25) = 10.307."""
    from offline.adapt.share_rule import T_ISF_3SIGMA, t_spreads_required

    assert t_spreads_required(1) is None
    assert t_spreads_required(4) == pytest.approx(9.2189 * np.sqrt(1.25), rel=1e-6)
    assert t_spreads_required(31) == pytest.approx(3.2703 * np.sqrt(1 + 1 / 31), rel=1e-6)
    # Many flights: back toward the Gaussian 3 (first-order expansion past the table, continuous at its end).
    assert 3.0 < t_spreads_required(1000) < 3.02
    assert abs(t_spreads_required(32) - t_spreads_required(31)) < 0.05
    stats = pytest.importorskip("scipy.stats")
    tail = stats.norm.sf(3.0)
    assert T_ISF_3SIGMA == pytest.approx([stats.t.isf(tail, df) for df in range(1, 31)], abs=1e-4)


def test_compare_reports_the_t_rule_beside_the_3_spread_rule(healthy_log):
    """Rotor 1 at 5 spreads above a 4-flight baseline: beyond 3 spreads, not beyond the t rule's 10.31."""
    from monitor.logs import read_log
    from offline.adapt.share_rule import flight_shares

    table = read_log(healthy_log)
    seen, basis = flight_shares(table)
    mean = seen + np.array([-0.1, 0.1 / 3, 0.1 / 3, 0.1 / 3])
    b = HealthyBaseline(basis, tuple(mean), (0.0,) * 4, (0.05,) * 4, None, 20.0, 4, ("a",), ("1", "2", "3", "4"))
    res = b.compare(table)
    assert res["rotors_beyond_3_spreads"] == [1]
    assert res["t_spreads_required"] == pytest.approx(10.31) and res["rotors_beyond_t_spreads"] == []
    one = HealthyBaseline(basis, tuple(mean), (0.0,) * 4, (0.05,) * 4, None, 20.0, 1, ("a",), ("1", "2", "3", "4"))
    assert one.compare(table)["t_spreads_required"] is None and one.compare(table)["rotors_beyond_t_spreads"] is None
