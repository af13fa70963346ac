"""The paper's 16 fault labels (Tong et al., Fig. 10 and Fig. 30).

Propellers are numbered 1..4 in PX4 quad-X order: 1 front-right CCW,
2 rear-left CCW, 3 front-left CW, 4 rear-right CW.

| label | faulty propellers |
| 1     | none |
| 2-5   | 1, 2, 3, 4 alone |
| 6-11  | (1,2) (1,3) (1,4) (2,3) (2,4) (3,4) |
| 12-15 | triples leaving out 4, 3, 2, 1: (1,2,3) (1,2,4) (1,3,4) (2,3,4) |
| 16    | all four |
"""

from __future__ import annotations

import numpy as np

N_LABELS = 16
N_PROPS = 4

LABEL_TABLE: dict[int, tuple[int, ...]] = {
    1: (),
    2: (1,),
    3: (2,),
    4: (3,),
    5: (4,),
    6: (1, 2),
    7: (1, 3),
    8: (1, 4),
    9: (2, 3),
    10: (2, 4),
    11: (3, 4),
    12: (1, 2, 3),
    13: (1, 2, 4),
    14: (1, 3, 4),
    15: (2, 3, 4),
    16: (1, 2, 3, 4),
}
_BY_SET = {frozenset(v): k for k, v in LABEL_TABLE.items()}

# Row k-1 is the 0/1 fault mask of label k; (16, 4) float32.
LABEL_MASKS = np.array(
    [[1.0 if p in LABEL_TABLE[k] else 0.0 for p in range(1, N_PROPS + 1)] for k in range(1, N_LABELS + 1)],
    dtype=np.float32,
)


def class_names() -> list[str]:
    return ["none" if not v else "faulty " + ",".join(map(str, v)) for v in LABEL_TABLE.values()]


def label_for(faulty_propellers) -> int:
    """Label (1..16) for a collection of faulty propeller numbers (1..4)."""
    key = frozenset(int(p) for p in faulty_propellers)
    if key not in _BY_SET:
        raise ValueError(f"faulty propellers must be a subset of 1..4, got {sorted(key)}")
    return _BY_SET[key]


def faulty_for(label: int) -> tuple[int, ...]:
    if label not in LABEL_TABLE:
        raise ValueError(f"label must be 1..16, got {label}")
    return LABEL_TABLE[label]


def label_from_mask(mask) -> int:
    """Label for a length-4 boolean fault mask."""
    m = np.asarray(mask, dtype=bool).reshape(N_PROPS)
    return label_for([i + 1 for i in range(N_PROPS) if m[i]])


def fault_probability_from_label_probs(label_probs: np.ndarray) -> np.ndarray:
    """Marginal P(propeller i faulty) from (..., 16) label probabilities -> (..., 4)."""
    return np.asarray(label_probs, dtype=np.float64) @ LABEL_MASKS.astype(np.float64)
