"""The reference's per-frame step in its own module (``host.judge.refodometry``, compiled by mypyc
under ``ODOCAN_ACCEL=1``): re-exported by ``reference``, numpy-free, and its twins (``copy.copy``,
which a compiled class cannot do from a ``__dict__``) in the very state of the original."""

from __future__ import annotations

import ast
import copy
import random

from odocan.host import accel
from odocan.host.judge import reference, refodometry

GEOMETRY = reference.Geometry(4096, 0.0501, 0.0499, 0.23)
STATE = ("x_m", "y_m", "distance_m", "heading_rad", "integrator", "counter_bits", "_prev",
         "_cum_left", "_cum_right", "_heading0_rad", "_m_left", "_m_right", "_k_left", "_k_right")


def _state(odometry: refodometry.ReferenceOdometry) -> tuple[object, ...]:
    return tuple(getattr(odometry, name) for name in STATE)


def test_reference_reexports_the_step() -> None:
    assert reference.ReferenceOdometry is refodometry.ReferenceOdometry
    assert reference.chord_factor is refodometry.chord_factor
    assert reference.INTEGRATORS is refodometry.INTEGRATORS


def test_compiled_and_numpy_free() -> None:
    """In ``MODULES``, and no numpy import (mypyc compiles it; numpy's types it refuses)."""
    assert "host.judge.refodometry" in accel.MODULES
    tree = ast.parse((accel.PACKAGE / "host" / "judge" / "refodometry.py").read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                for alias in node.names}
    imported |= {node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert not any(name.split(".")[0] == "numpy" for name in imported), imported


def test_wrap_delta_int_is_reference_wrap_delta() -> None:
    rng = random.Random(13)
    for bits in (8, 16, 24, 32):
        for _ in range(500):
            delta = rng.randrange(-(1 << (bits + 1)), 1 << (bits + 1))
            assert refodometry.wrap_delta_int(delta, bits) == reference.wrap_delta(delta, bits)


def test_a_copy_is_a_twin_in_the_same_state() -> None:
    """``copy.copy`` mid-drive: every attribute equal, then both stepped alike stay equal, and
    stepping one leaves the other where it was (livechoice's and haltpath's twins)."""
    rng = random.Random(4)
    for integrator in reference.INTEGRATORS:
        ref = reference.ReferenceOdometry(GEOMETRY, integrator, 24, x_m=0.3, heading_rad=0.2)
        counts = [0, 0]
        for _ in range(50):
            counts = [(c + rng.randrange(-40, 90)) % (1 << 24) for c in counts]
            ref.step_counts(*counts)
        ref.place(1.0, -2.0, 0.5)
        twin = copy.copy(ref)
        assert twin is not ref
        assert _state(twin) == _state(ref)
        before, steps = _state(ref), []
        for _ in range(20):
            counts = [(c + rng.randrange(-40, 90)) % (1 << 24) for c in counts]
            steps.append(tuple(counts))
            twin.step_counts(*counts)
        assert _state(ref) == before
        assert _state(twin) != before
        for step in steps:  # the same steps on the original: the very same floats
            ref.step_counts(*step)
        assert _state(twin) == _state(ref), integrator
