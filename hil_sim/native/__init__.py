"""Compiled twins of the simulation's pure arithmetic, used in process when a C compiler works.

- :mod:`pressor.hil_sim.native.controller`: the shipped LPV module's double-precision C twin (committed beside
  it by ``pressor codegen``);
- :mod:`pressor.hil_sim.native.estimator`: the online estimator (sample gate, window noise, delay bank,
  selection), ``delay_bank.c``;
- :mod:`pressor.hil_sim.native.patient`: the paper's nonlinear patient, ``paper_patient.c``;
- :mod:`pressor.hil_sim.native.drug_patient`: the ``pkpd``, ``phenylephrine-2c`` and
  ``norepinephrine`` patients, ``drug_patients.c``;
- :mod:`pressor.hil_sim.native.dose_guard`: the hourly dose limit's bookkeeping (the supervisor's
  :class:`~pressor.runtime.core.dose_guard.DoseGuard`, under the drug library's limits),
  ``dose_guard.c``.

Each twin gives the same IEEE double results as the Python it stands in for (checked bit for bit
in ``tests/hil_sim/native``), so a trial's records are the same bytes with or without them; they only
make a cohort faster (docs/notes/benchmarks.md, "Trial throughput"). Flags, the per-user cache and
``PRESSOR_NATIVE=off``: :mod:`pressor.plumbing.native_build`. The bedside runtime never uses them:
``pressor run`` steps the hash-checked Python module and the Python estimator.
"""
