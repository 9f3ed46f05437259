"""Offline design of the delay-dependent LPV MAP controller (cvxpy + Clarabel).

What ships: the ``smith`` family, a closed-form scheduled Smith predictor + PI in the paper's
controller class, certified by the Wirtinger analysis LMI in K-scaled coordinates. Its path::

    cli.py (pressor synth)
      -> problem/config_toml.py              the design TOML -> DesignConfig
      -> families/registry.py                the config's family name -> its family object
      -> families/smith/family.py            SmithFamily.design, calls
           families/smith/design.py          builds the law and certifies it:
           families/smith/law.py             the closed-form law at any frozen ρ
           certificates/wirtinger/           the analysis LMI (analysis.py, lmi.py, conic.py)
      -> artifact.py                         the typed artifact between stages (.npz)
    verify_cli.py (pressor verify)
      -> verification/verify.py              check (a) via the family, delay stability, steps
    problem/reconstruct.py                   the controller at ρ of any artifact (codegen reads it)

Subpackages, lowest first (imports point only downward, ``tests/test_layers.py``):
``solver/`` (conic solve, KKT chain, BLAS pin) and ``families/registry.py`` (names only);
``problem/`` (model, config, closed loop, scaling, prefilter, ρ-basis, reconstruction);
``artifact.py``; ``certificates/`` (``wirtinger/`` shipped, ``jensen/`` only for theorem3
artifacts); ``families/smith/`` (shipped) and ``families/theorem3/`` (the alternative: the
paper's Theorem-3 synthesis LMIs); ``verification/``; ``research/`` (benchmark-only formulations,
nothing in ``pressor`` imports it); ``cli.py``, ``verify_cli.py`` on top.

Imports no I/O-heavy package (no serial, no rerun); nothing in ``runtime/`` imports this package.
"""
