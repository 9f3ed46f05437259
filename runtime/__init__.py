"""The bedside runtime: what ``pressor run`` ships, in one screen.

``pressor run`` (:mod:`runtime.cli`) checks its options (:mod:`runtime.inputs`), opens the serial
port and hands it to :func:`runtime.session.run_runtime`: handshake over the separate ``link``
package, load and check the controller, build the supervisor and the scheduling source, then the
fixed-rate loop (:mod:`runtime.shell`) steps the pure per-tick closed loop (:mod:`runtime.core`)
once per period and records each tick (:mod:`runtime.record`); at the end :mod:`runtime.summary`
prints and writes the run's metrics. :mod:`runtime.estimation` is the online K/T/τ estimator behind
``--schedule estimated``; :mod:`runtime.generated` holds the generated controller modules. Parts
import one way (docs/ARCHITECTURE.md, ``tests/test_layers.py``): core at the bottom, cli on top.

Never imports ``synthesis``, ``cvxpy`` or ``sim``: a bedside box has no solver and no simulated
patient. Keep this ``__init__`` free of imports so that light modules (``contracts.controller``,
``baselines.pi``, ``contracts.metrics``) load without serial or rerun.
"""
