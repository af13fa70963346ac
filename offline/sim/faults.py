"""Analytic fault signatures of a propeller: how a bent or cracked blade departs from kF·ω², kτ·ω².

Everything is written against the normalised speed ``s = omega / omega_max``
(0..1) so that one signature serves any vehicle whose normal propeller obeys
``thrust = kF·ω²`` and ``torque = kτ·ω²``. The virtual load cell
(``offline.propellers.loadcell``) measures these signatures; the simulator's
``kind="quadratic"`` propellers apply them directly.

Physical argument for each term (magnitudes are defaults, chosen realistic but
detectable; none is measured, since no public damaged-propeller load-cell data
exists -- see ../shared/data/README.md):

Bent blade (``BENT``)
    A bent blade has its tip twisted out of the design pitch and out of the
    rotor plane. The plastic deformation is there at rest, so the thrust
    coefficient is already lower at low speed (-8 %); under load the weakened,
    bent section flexes further (blade bending moment grows with lift, i.e.
    with ω²), so the loss grows to -12 % at full speed. The disturbed blade
    sheds a stronger tip vortex and runs at off-design angle of attack: more
    profile drag, hence more drag torque (+5 % growing to +10 %). The two
    blades no longer produce equal lift: a once-per-revolution (1P) thrust and
    torque ripple (4 % and 3 % of the mean).

Cracked blade (``CRACKED``)
    A crack near the root is nearly closed at low speed (-3 % thrust), but it
    opens under centrifugal and aerodynamic load, both proportional to ω²: the
    outer blade twists and flexes, so the loss grows with RPM to -15 % at full
    speed. The loose section flutters: broadband, RPM-dependent thrust and
    torque fluctuations (relative std up to 3 % and 2 % at full speed,
    correlation time ~10 ms), plus a small 1P ripple from the asymmetry.
    Drag torque rises less than for a bent blade (+2 % to +6 %): the crack
    adds profile drag while the lost lift removes some induced drag.

The mean terms are ``thrust_factor(s) = 1 - (loss_low + (loss_high - loss_low)·s²)``
and ``torque_factor(s) = 1 + (gain_low + (gain_high - gain_low)·s²)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONDITIONS = ("normal", "bent", "cracked")


@dataclass(frozen=True)
class FaultSignature:
    """One condition's departure from the normal propeller; fractions of the normal value."""

    thrust_loss_low: float = 0.0  # at s -> 0
    thrust_loss_high: float = 0.0  # at s = 1 (omega_max)
    torque_gain_low: float = 0.0
    torque_gain_high: float = 0.0
    ripple_1p_thrust: float = 0.0  # once-per-revolution amplitude, fraction of mean thrust
    ripple_1p_torque: float = 0.0
    flutter_thrust_std: float = 0.0  # relative std at s = 1, scales with s²
    flutter_torque_std: float = 0.0
    flutter_time_constant_s: float = 0.01

    def thrust_factor(self, s: np.ndarray) -> np.ndarray:
        s2 = np.square(np.clip(s, 0.0, None))
        return 1.0 - (self.thrust_loss_low + (self.thrust_loss_high - self.thrust_loss_low) * s2)

    def torque_factor(self, s: np.ndarray) -> np.ndarray:
        s2 = np.square(np.clip(s, 0.0, None))
        return 1.0 + (self.torque_gain_low + (self.torque_gain_high - self.torque_gain_low) * s2)

    @property
    def has_vibration(self) -> bool:
        return any(
            v > 0 for v in (self.ripple_1p_thrust, self.ripple_1p_torque, self.flutter_thrust_std, self.flutter_torque_std)
        )


NORMAL = FaultSignature()
BENT = FaultSignature(
    thrust_loss_low=0.08,
    thrust_loss_high=0.12,
    torque_gain_low=0.05,
    torque_gain_high=0.10,
    ripple_1p_thrust=0.04,
    ripple_1p_torque=0.03,
)
CRACKED = FaultSignature(
    thrust_loss_low=0.03,
    thrust_loss_high=0.15,
    torque_gain_low=0.02,
    torque_gain_high=0.06,
    ripple_1p_thrust=0.01,
    ripple_1p_torque=0.01,
    flutter_thrust_std=0.03,
    flutter_torque_std=0.02,
    flutter_time_constant_s=0.01,
)

SIGNATURES: dict[str, FaultSignature] = {"normal": NORMAL, "bent": BENT, "cracked": CRACKED}


def signature_table(signatures: dict[str, FaultSignature] | None = None) -> tuple[FaultSignature, ...]:
    """Signatures indexed by condition code (0 normal, 1 bent, 2 cracked)."""
    sig = SIGNATURES if signatures is None else signatures
    return tuple(sig[name] for name in CONDITIONS)
