"""The frozen-loop check tells a stable sampled loop from an unstable one (pressor.codegen.frozen_loop)."""

from __future__ import annotations

from pressor.codegen.discretise import DelayedControllerMatrices, discretise_node
from pressor.codegen.frozen_loop import frozen_loop_matrices, unstable_root_count
from tests.support.codegen_helpers import TS, example_controller


def test_frozen_loop_check_tells_stable_from_unstable():
    rho = (0.55, 150.0, 40.0)
    c = example_controller(rho)
    m = discretise_node(c, 0.1, 0.1, TS)
    assert unstable_root_count(frozen_loop_matrices(m, rho, TS)) == 0
    hot = DelayedControllerMatrices(c.Ak, c.Adk, c.Bk, c.Ck, c.Cdk, c.Dk * 8.0)
    m8 = discretise_node(hot, 0.1, 0.1, TS)
    assert unstable_root_count(frozen_loop_matrices(m8, rho, TS)) > 0
