"""The bedside runtime: what ``pressor run`` ships, in one screen.

``pressor run`` (:mod:`pressor.runtime.cli`) checks its options (:mod:`pressor.runtime.inputs`), opens the serial
port and hands it to :func:`pressor.runtime.session.run_runtime`: handshake over the separate ``link``
package, load and check the controller, build the supervisor and the scheduling source, then the
fixed-rate loop (:mod:`pressor.runtime.shell`) steps the pure per-tick closed loop (:mod:`pressor.runtime.core`)
once per period and records each tick (:mod:`pressor.runtime.record`); at the end :mod:`pressor.runtime.summary`
prints and writes the run's metrics. :mod:`pressor.runtime.estimation` is the online K/T/τ estimator behind
``--schedule estimated``; :mod:`pressor.runtime.generated` holds the generated controller modules. Parts
import one way (docs/ARCHITECTURE.md, ``tests/test_layers.py``): core at the bottom, cli on top.

Never imports ``synthesis``, ``cvxpy`` or ``hil_sim``: a bedside box has no solver and no simulated
patient. Keep this ``__init__`` free of imports so that light modules (``pressor.contracts.controller``,
``pressor.baselines.pi``, ``pressor.contracts.metrics``) load without serial or rerun.
"""
