"""The decision-vector layout of the synthesis LMI packs and unpacks without loss."""

from __future__ import annotations

import numpy as np

from pressor.synthesis.families.theorem3 import lmi
from pressor.synthesis.problem.config_toml import load_config


def test_layout_pack_inverts_unpack():
    lay = lmi.make_problem(load_config().with_grid((2, 2, 2))).layout
    x = np.random.default_rng(4).normal(size=lay.nvar)
    vals = {k: v[0] for k, v in lay.unpack(x[None, :]).items()}
    np.testing.assert_array_equal(lay.pack(vals), x)
