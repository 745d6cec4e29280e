"""Seeds of the experiments' runs: one independent, reproducible stream per (seed, experiment, run).

``run_seed(seed, code, index)`` hashes the three integers with numpy's ``SeedSequence`` into a
63-bit seed for the rig (the slip noise); ``run_rng`` gives a Generator for the host's own draws
(e.g. the initial misalignment). Run 3 of seed 0 and run 2 of seed 1 share nothing.
"""

from __future__ import annotations

import numpy as np

from odocan.sim.exceptions import ConfigurationError


def _sequence(seed: int, code: int, index: int) -> np.random.SeedSequence:
    if seed < 0:
        raise ConfigurationError(f"--seed must be a non-negative integer, got {seed}")
    return np.random.SeedSequence([seed, code, index])


def run_seed(seed: int, code: int, index: int) -> int:
    """A rig seed (0 .. 2^63 - 1) for run ``index`` of experiment ``code`` under ``seed``."""
    return int(_sequence(seed, code, index).generate_state(1, np.uint64)[0] >> np.uint64(1))


def run_rng(seed: int, code: int, index: int) -> np.random.Generator:
    """A Generator for the host's draws of that run (independent of the rig's stream)."""
    return np.random.default_rng(_sequence(seed, code, index).spawn(1)[0])
